//! The aggregate of a sweep: `report.md` with a table per run, metrics per spp, the loss curves
//! (`curves.csv`, `train-loss.svg`, `test-loss.svg`), error against run time, and the thesis's claims.

use std::collections::BTreeSet;
use std::fmt::Write;
use std::path::Path;

use super::claims::{Claim, PSNR_MARGIN_DB, claims};
use super::plot;
use super::results::{RunResult, mean};
use super::spec::{Scale, Sweep, flags};
use crate::util::Result;

fn opt(v: Option<f64>, digits: usize) -> String {
    v.filter(|x| x.is_finite()).map_or("–".into(), |x| format!("{x:.digits$}"))
}

fn write_file(path: &Path, text: &str) -> Result<()> {
    let tmp = path.with_extension("tmp");
    std::fs::write(&tmp, text).map_err(|e| format!("{}: {e}", tmp.display()))?;
    std::fs::rename(&tmp, path).map_err(|e| format!("{}: {e}", path.display()))
}

/// Writes the report of one sweep into `dir` and returns its claims.
pub fn write(sweep: &Sweep, scale: &Scale, results: &[RunResult], dir: &Path) -> Result<Vec<Claim>> {
    std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let done: Vec<&RunResult> = results.iter().filter(|r| r.done).collect();
    let mut md = String::new();
    let _ = writeln!(md, "# Sweep `{}` at scale `{}`\n\n{}\n", sweep.name, scale.name, sweep.description);
    let _ = writeln!(
        md,
        "{} of {} runs complete. Reproduce: `cargo xtask sweep {} --scale {}`.\n",
        done.len(),
        results.len(),
        sweep.name,
        scale.name
    );
    let missing: Vec<&str> = results.iter().filter(|r| !r.done).map(|r| r.run.name.as_str()).collect();
    if !missing.is_empty() {
        let _ = writeln!(md, "Not complete: {}.\n", missing.join(", "));
    }

    // Runs.
    let _ = writeln!(md, "## Runs\n");
    let _ = writeln!(
        md,
        "Test metrics are means over the test views and spp of the final model (`hush eval`); losses are those \
         of `hush train`'s `metrics.csv` (test loss on whole test images).\n"
    );
    // The flags every run shares are shown once; the table shows those that differ.
    let mut common = done.first().map(|r| r.run.train.clone()).unwrap_or_default();
    common.retain(|k, v| done.iter().all(|r| r.run.train.get(k) == Some(v)));
    let _ = writeln!(md, "Every run: `hush train {}`.\n", flags(&common).join(" "));
    let _ = writeln!(
        md,
        "| run | other flags | epochs | s/epoch | train loss | test loss | best test loss (epoch) | gap | PSNR | \
         SSIM | MAE | relMSE | denoise s |"
    );
    let _ = writeln!(md, "|---|---|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|");
    for r in &done {
        let rows = r.model_rows();
        let m = |f: &dyn Fn(&super::results::EvalRow) -> Option<f64>| mean(rows.iter().filter_map(|x| f(x)));
        let last = r.last_tested();
        let _ = writeln!(
            md,
            "| {} | `{}` | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |",
            r.run.name,
            flags(
                &r.run
                    .train
                    .iter()
                    .filter(|(k, _)| !common.contains_key(*k))
                    .map(|(k, v)| (k.clone(), v.clone()))
                    .collect()
            )
            .join(" "),
            r.epochs.last().map_or(0, |e| e.epoch),
            opt(r.seconds_per_epoch(), 2),
            opt(last.map(|l| l.1), 4),
            opt(last.map(|l| l.2), 4),
            r.best().map_or("–".into(), |(e, l)| format!("{l:.4} ({e})")),
            opt(last.map(|l| l.2 - l.1), 4),
            opt(m(&|x| x.psnr), 2),
            opt(m(&|x| x.ssim), 4),
            opt(m(&|x| x.mae), 4),
            opt(m(&|x| x.rel_mse), 4),
            opt(m(&|x| x.denoise_seconds), 3),
        );
    }

    // Per spp.
    let spps: BTreeSet<u64> = done.iter().flat_map(|r| r.model_rows()).map(|r| r.spp).collect();
    if !spps.is_empty() {
        let _ = writeln!(md, "\n## PSNR (dB) / SSIM per spp\n\nMeans over the test views.\n");
        let head: Vec<String> = spps.iter().map(|s| format!("{s} spp")).collect();
        let _ = writeln!(md, "| method | {} |", head.join(" | "));
        let _ = writeln!(md, "|---|{}", "--:|".repeat(spps.len()));
        let cell = |rows: &[&super::results::EvalRow], spp: u64| {
            let at: Vec<_> = rows.iter().filter(|r| r.spp == spp).collect();
            format!(
                "{} / {}",
                opt(mean(at.iter().filter_map(|r| r.psnr)), 2),
                opt(mean(at.iter().filter_map(|r| r.ssim)), 4)
            )
        };
        if let Some(first) = done.first() {
            let noisy = first.noisy_rows();
            let _ =
                writeln!(md, "| noisy | {} |", spps.iter().map(|&s| cell(&noisy, s)).collect::<Vec<_>>().join(" | "));
        }
        for r in &done {
            let rows = r.model_rows();
            let _ = writeln!(
                md,
                "| {} | {} |",
                r.run.name,
                spps.iter().map(|&s| cell(&rows, s)).collect::<Vec<_>>().join(" | ")
            );
        }
    }

    // Images: one test view at the lowest spp, noisy and every run's result.
    if let Some((view, spp)) =
        done.iter().flat_map(|r| r.model_rows()).map(|r| (r.view.clone(), r.spp)).min_by_key(|k| k.1)
    {
        let at = |r: &RunResult, noisy: bool| {
            let rows = if noisy { r.noisy_rows() } else { r.model_rows() };
            let row = rows.into_iter().find(|x| x.view == view && x.spp == spp)?;
            Some(format!("{}/eval/{}", r.run.name, row.preview.as_ref()?))
        };
        let mut head = vec!["noisy".to_string()];
        let mut cells = vec![done.iter().find_map(|r| at(r, true)).map_or("–".into(), |p| format!("![noisy]({p})"))];
        for r in &done {
            head.push(r.run.name.clone());
            cells.push(at(r, false).map_or("–".into(), |p| format!("![{}]({p})", r.run.name)));
        }
        let _ = writeln!(md, "\n## Images\n\n{view} at {spp} spp (tonemapped previews of `hush eval`).\n");
        let _ = writeln!(md, "| {} |\n|{}\n| {} |", head.join(" | "), "---|".repeat(head.len()), cells.join(" | "));
        md += &crops_and_differences(&done, &view, spp);
    }

    // Error against run time.
    if let Some(section) = error_vs_time(&done, |r| r.run.name.clone(), &sweep.name, dir)? {
        md += &section;
    }

    // Curves.
    let mut csv = String::from("run,epoch,train_loss,test_loss,seconds\n");
    for r in &done {
        for e in &r.epochs {
            let _ = writeln!(
                csv,
                "{},{},{},{},{}",
                r.run.name,
                e.epoch,
                e.train_loss,
                e.test_loss.map(|t| t.to_string()).unwrap_or_default(),
                e.seconds
            );
        }
    }
    write_file(&dir.join("curves.csv"), &csv)?;
    let train: Vec<plot::Series> = done
        .iter()
        .map(|r| (r.run.name.clone(), r.epochs.iter().map(|e| (e.epoch as f64, e.train_loss)).collect()))
        .collect();
    let test: Vec<plot::Series> = done
        .iter()
        .map(|r| (r.run.name.clone(), r.epochs.iter().filter_map(|e| Some((e.epoch as f64, e.test_loss?))).collect()))
        .collect();
    let _ = writeln!(md, "\n## Loss over epochs\n\nAll rows: `curves.csv`.\n");
    for (file, title, series) in [("train-loss.svg", "training loss", &train), ("test-loss.svg", "test loss", &test)] {
        if let Some(svg) = plot::lines(&format!("{}: {title}", sweep.name), "epoch", title, series, true) {
            write_file(&dir.join(file), &svg)?;
            let _ = writeln!(md, "![{title}]({file})\n");
        }
    }
    // A compact table of the test loss at up to 12 evaluated epochs.
    let epochs: BTreeSet<usize> =
        done.iter().flat_map(|r| r.epochs.iter().filter(|e| e.test_loss.is_some()).map(|e| e.epoch)).collect();
    if !epochs.is_empty() {
        let list: Vec<usize> = epochs.iter().copied().collect();
        let stride = list.len().div_ceil(12);
        let mut picked: Vec<usize> = list.iter().copied().step_by(stride).collect();
        if picked.last() != list.last() {
            picked.push(*list.last().expect("not empty"));
        }
        let _ = writeln!(md, "Test loss by epoch (train loss in parentheses):\n");
        let _ = writeln!(md, "| run | {} |", picked.iter().map(|e| format!("{e}")).collect::<Vec<_>>().join(" | "));
        let _ = writeln!(md, "|---|{}", "--:|".repeat(picked.len()));
        for r in &done {
            let cells: Vec<String> = picked
                .iter()
                .map(|&p| match r.epochs.iter().find(|e| e.epoch == p) {
                    Some(e) => format!("{} ({:.4})", opt(e.test_loss, 4), e.train_loss),
                    None => "–".into(),
                })
                .collect();
            let _ = writeln!(md, "| {} | {} |", r.run.name, cells.join(" | "));
        }
    }

    // Claims.
    let claims = claims(&sweep.name, results);
    md += &claims_section(&claims);
    write_file(&dir.join("report.md"), &md)?;
    write_file(&dir.join("report.html"), &html(&md, &format!("{} at {}", sweep.name, scale.name)))?;
    Ok(claims)
}

/// Per run, its model's crop of the window where the noisy input is worst and its difference picture against
/// the reference, as `hush eval` drew them (the thesis's figures 7.5–7.7 compare the losses this way); the
/// noisy input and the reference first. Empty if no run has pictures.
fn crops_and_differences(done: &[&RunResult], view: &str, spp: u64) -> String {
    let image = |r: &RunResult, path: Option<&str>, alt: &str| {
        path.map_or("–".to_string(), |p| format!("![{alt}]({}/eval/{p})", r.run.name))
    };
    let mut rows = Vec::new();
    if let Some(r) = done.iter().find(|r| r.crop(view, spp, "reference").is_some()) {
        rows.push(format!("| reference | {} | – | – |", image(r, r.crop(view, spp, "reference"), "reference")));
    }
    if let Some(r) = done.iter().find(|r| r.crop(view, spp, "noisy").is_some()) {
        let (diff, shares) = r.difference(view, spp, "noisy").unzip();
        let diff = image(r, diff, "noisy: pixels off");
        rows.push(format!(
            "| noisy | {} | {diff} | {} |",
            image(r, r.crop(view, spp, "noisy"), "noisy"),
            shares.unwrap_or("–")
        ));
    }
    let before = rows.len();
    for r in done {
        let Some(method) = r.model_rows().first().map(|m| m.method.clone()) else { continue };
        let Some(crop) = r.crop(view, spp, &method) else { continue };
        let (diff, shares) = r.difference(view, spp, &method).unzip();
        let name = &r.run.name;
        let diff = image(r, diff, &format!("{name}: pixels off"));
        rows.push(format!("| {name} | {} | {diff} | {} |", image(r, Some(crop), name), shares.unwrap_or("–")));
    }
    if rows.len() == before {
        return String::new();
    }
    format!(
        "\n## Crops and differences\n\n{view} at {spp} spp: each run's denoised crop of the window where the noisy \
         input is worst, and its pixels off the reference by more than 3 % (yellow) and 10 % (red) after the \
         evaluation tonemap, as in the thesis's figures 7.5–7.7 (`hush eval`'s pictures).\n\n\
         | run | crop | pixels off | share > 3 %, > 10 % |\n|---|---|---|---|\n{}\n",
        rows.join("\n")
    )
}

/// The error-against-run-time table of `runs` (named by `label`) and its plot `error-vs-time.svg` in `dir`.
fn error_vs_time(
    runs: &[&RunResult],
    label: impl Fn(&RunResult) -> String,
    title: &str,
    dir: &Path,
) -> Result<Option<String>> {
    let Some(first) = runs.first() else { return Ok(None) };
    let spps: BTreeSet<u64> = runs.iter().flat_map(|r| r.model_rows()).map(|r| r.spp).collect();
    let mut md = String::from(
        "\n## Error against run time\n\nPer spp: the noisy render's seconds, then each model's render + denoise \
         seconds and PSNR (means over the test views).\n\n| spp | method | render s | denoise s | total s | PSNR (dB) |\n\
         |--:|---|--:|--:|--:|--:|\n",
    );
    let mut series: Vec<plot::Series> = Vec::new();
    for run in std::iter::once(None).chain(runs.iter().map(|r| Some(*r))) {
        let name = run.map_or("noisy".into(), &label);
        let mut points = Vec::new();
        for &spp in &spps {
            let noisy: Vec<_> = first.noisy_rows().into_iter().filter(|r| r.spp == spp).collect();
            let render = mean(noisy.iter().filter_map(|r| r.render_seconds));
            let rows: Vec<_> = match run {
                Some(r) => r.model_rows().into_iter().filter(|x| x.spp == spp).collect(),
                None => noisy,
            };
            let den = if run.is_some() { mean(rows.iter().filter_map(|x| x.denoise_seconds)) } else { Some(0.0) };
            let total = render.zip(den).map(|(a, b)| a + b);
            let psnr = mean(rows.iter().filter_map(|x| x.psnr));
            let den_cell = if run.is_some() { opt(den, 3) } else { "–".into() };
            let _ = writeln!(
                md,
                "| {spp} | {name} | {} | {den_cell} | {} | {} |",
                opt(render, 2),
                opt(total, 2),
                opt(psnr, 2)
            );
            if let (Some(t), Some(p)) = (total, psnr) {
                points.push((t, p));
            }
        }
        points.sort_by(|a, b| a.0.total_cmp(&b.0));
        series.push((name, points));
    }
    let title = format!("{title}: PSNR against render + denoise seconds");
    if let Some(svg) = plot::lines(&title, "seconds", "PSNR (dB)", &series, false) {
        write_file(&dir.join("error-vs-time.svg"), &svg)?;
        md += "\n![error against run time](error-vs-time.svg)\n";
    }
    Ok(Some(md))
}

/// The claims table with the rule that decided them.
pub fn claims_section(claims: &[Claim]) -> String {
    let mut md = String::new();
    if claims.is_empty() {
        return md;
    }
    let _ = writeln!(
        md,
        "\n## The thesis's findings\n\nRule: runs A and B are compared on the rows of the same seed, test view and spp; \
         d̄ is the mean of the differences (positive = the thesis's direction), SE their standard error. \
         Reproduced when d̄ > 2·SE, refuted when d̄ < −2·SE, inconclusive otherwise or with fewer than 2 pairs. \
         \"Little difference\" claims: reproduced when |d̄| + 2·SE < {PSNR_MARGIN_DB} dB, refuted when |d̄| − 2·SE > \
         {PSNR_MARGIN_DB} dB. Rows of one view at several spp are not independent: SE is optimistic. Timing claims \
         compare wall seconds per epoch, which on a shared machine are only comparable under equal load (each run's \
         `done.json` records the load average).\n"
    );
    let _ = writeln!(md, "| sweep | thesis | measured | verdict |");
    let _ = writeln!(md, "|---|---|---|---|");
    for c in claims {
        let _ = writeln!(md, "| {} | {} | {} | {} |", c.sweep, c.thesis, c.measured, c.verdict);
    }
    md
}

/// The report of `all`: every model's error against run time and every sweep's claims, with links to the
/// sweeps' reports.
pub fn write_all(scale: &Scale, sweeps: &[(String, Vec<Claim>)], results: &[RunResult], dir: &Path) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let mut md = format!("# Every sweep at scale `{}`\n\n{}\n\n", scale.name, scale_note(scale));
    for (name, _) in sweeps {
        let _ = writeln!(md, "- [{name}](../../{name}/{}/report.md)", scale.name);
    }
    let done: Vec<&RunResult> = results.iter().filter(|r| r.done).collect();
    if let Some(section) = error_vs_time(&done, |r| format!("{}/{}", r.run.sweep, r.run.name), "every model", dir)? {
        md += &section;
    }
    let all: Vec<Claim> = sweeps.iter().flat_map(|(_, c)| c.iter().cloned()).collect();
    md += &claims_section(&all);
    write_file(&dir.join("report.md"), &md)?;
    write_file(&dir.join("report.html"), &html(&md, &format!("every sweep at {}", scale.name)))
}

/// Inline Markdown of the reports (code, bold, images, links) as HTML.
fn inline(text: &str) -> String {
    let mut t = text.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;");
    for (mark, open, close) in [("`", "<code>", "</code>"), ("**", "<b>", "</b>")] {
        let mut out = String::new();
        let mut parts = t.split(mark).peekable();
        let mut odd = false;
        while let Some(p) = parts.next() {
            out += p;
            if parts.peek().is_some() {
                out += if odd { close } else { open };
                odd = !odd;
            }
        }
        t = out;
    }
    // ![alt](src) and [text](href); links to reports go to their HTML twins.
    let mut out = String::new();
    let mut rest = t.as_str();
    while let Some(i) = rest.find('[') {
        let image = i > 0 && rest.as_bytes()[i - 1] == b'!';
        let parsed = rest[i..].find("](").and_then(|j| Some((j, rest[i + j..].find(')')? + i + j)));
        let Some((j, k)) = parsed else { break };
        let (label, target) = (&rest[i + 1..i + j], &rest[i + j + 2..k]);
        out += &rest[..if image { i - 1 } else { i }];
        out += &if image {
            format!("<img src=\"{target}\" alt=\"{label}\" style=\"max-width:100%\">")
        } else {
            format!("<a href=\"{}\">{label}</a>", target.replace("report.md", "report.html"))
        };
        rest = &rest[k + 1..];
    }
    out + rest
}

/// The report's Markdown (headings, paragraphs, lists, pipe tables) as a standalone HTML page.
pub fn html(md: &str, title: &str) -> String {
    let mut out = format!(
        "<!DOCTYPE html>\n<html><head><meta charset=\"utf-8\"><title>{}</title><style>body{{font-family:sans-serif;\
         max-width:1200px;margin:auto}}table{{border-collapse:collapse}}td,th{{border:1px solid #ccc;padding:2px 6px;\
         text-align:right}}td:first-child{{text-align:left}}</style></head><body>\n",
        inline(title)
    );
    let mut in_table = false;
    let mut in_list = false;
    for line in md.lines() {
        let cells = line.strip_prefix('|').and_then(|l| l.strip_suffix('|'));
        if in_table && cells.is_none() {
            out += "</table>\n";
            in_table = false;
        }
        if in_list && !line.starts_with("- ") {
            out += "</ul>\n";
            in_list = false;
        }
        if let Some(cells) = cells {
            let cells: Vec<&str> = cells.split('|').map(str::trim).collect();
            if cells.iter().all(|c| !c.is_empty() && c.chars().all(|ch| matches!(ch, '-' | ':'))) {
                continue;
            }
            let tag = if in_table { "td" } else { "th" };
            if !in_table {
                out += "<table>\n";
                in_table = true;
            }
            out += "<tr>";
            for c in cells {
                out += &format!("<{tag}>{}</{tag}>", inline(c));
            }
            out += "</tr>\n";
        } else if let Some(h) = line.strip_prefix("## ") {
            out += &format!("<h2>{}</h2>\n", inline(h));
        } else if let Some(h) = line.strip_prefix("# ") {
            out += &format!("<h1>{}</h1>\n", inline(h));
        } else if let Some(item) = line.strip_prefix("- ") {
            if !in_list {
                out += "<ul>\n";
                in_list = true;
            }
            out += &format!("<li>{}</li>\n", inline(item));
        } else if !line.trim().is_empty() {
            out += &format!("<p>{}</p>\n", inline(line));
        }
    }
    if in_table {
        out += "</table>\n";
    }
    if in_list {
        out += "</ul>\n";
    }
    out + "</body></html>\n"
}

fn scale_note(scale: &Scale) -> String {
    format!(
        "Dataset: `hush dataset {} {}`; every run also gets `{}`; seeds {:?}.",
        scale.scenes.join(" "),
        flags(&scale.dataset).join(" "),
        flags(&scale.train).join(" "),
        scale.seeds
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sweep::results::{Epoch, EvalRow, Picture};

    #[test]
    fn markdown_to_html() {
        let page =
            html("# T `x`\n\n- [a](a/report.md)\n\n| h | i |\n|---|--:|\n| **r** | 1 < 2 |\ntext ![p](q.png)\n", "t");
        for want in [
            "<h1>T <code>x</code></h1>",
            "<ul>\n<li><a href=\"a/report.html\">a</a></li>\n</ul>",
            "<table>\n<tr><th>h</th><th>i</th></tr>\n<tr><td><b>r</b></td><td>1 &lt; 2</td></tr>\n</table>",
            "<p>text <img src=\"q.png\" alt=\"p\" style=\"max-width:100%\"></p>",
        ] {
            assert!(page.contains(want), "missing {want:?} in {page}");
        }
    }
    use crate::sweep::spec::{parse_scales, parse_sweep};

    #[test]
    fn a_report_with_a_missing_run() {
        let scales = "[tiny]\nscenes=[\"a\"]\n[small]\nscenes=[\"a\"]\n[thesis]\nscenes=[\"a\"]\n";
        let scale = parse_scales(scales, Path::new("s.toml")).unwrap().remove(0);
        let text =
            "[[axis]]\nname = \"arch\"\nvariants = [{ name = \"oidn\" }, { name = \"dae\", arch = \"autoencoder\" }]";
        let sweep = parse_sweep("architecture", text, Path::new("a.toml")).unwrap();
        let runs = sweep.runs(&scale);
        let row = |method: &str, psnr| EvalRow {
            view: "v".into(),
            method: method.into(),
            spp: 4,
            psnr: Some(psnr),
            ssim: Some(0.5),
            mae: None,
            rel_mse: None,
            render_seconds: Some(2.0),
            denoise_seconds: (method != "noisy").then_some(0.5),
            preview: Some(format!("previews/{method}.png")),
        };
        let results = vec![
            RunResult {
                run: runs[0].clone(),
                done: true,
                epochs: vec![Epoch { epoch: 1, train_loss: 0.5, test_loss: Some(0.6), seconds: 3.0 }],
                eval: vec![row("noisy", 20.0), row("train/model", 25.0)],
                pictures: [
                    ("crops", "reference", "r.png"),
                    ("crops", "noisy", "n.png"),
                    ("crops", "train/model", "m.png"),
                    ("pixels off by more than 3 % and 10 %", "noisy: 40.0 % > 3 %, 9.0 % > 10 %", "nd.png"),
                    ("pixels off by more than 3 % and 10 %", "train/model: 12.5 % > 3 %, 1.0 % > 10 %", "md.png"),
                ]
                .map(|(t, c, p)| Picture { title: format!("v at 4 spp: {t}"), caption: c.into(), path: p.into() })
                .to_vec(),
            },
            RunResult { run: runs[1].clone(), done: false, epochs: vec![], eval: vec![], pictures: vec![] },
        ];
        let dir = std::env::temp_dir().join(format!("xtask-report-{}", std::process::id()));
        let claims = write(&sweep, &scale, &results, &dir).unwrap();
        let md = std::fs::read_to_string(dir.join("report.md")).unwrap();
        assert!(md.contains("1 of 2 runs complete"), "{md}");
        assert!(md.contains("Not complete: dae."));
        assert!(
            md.contains("| oidn | `` | 1 | 3.00 | 0.5000 | 0.6000 | 0.6000 (1) | 0.1000 | 25.00 | 0.5000 |"),
            "{md}"
        );
        assert!(md.contains("| 4 | oidn | 2.00 | 0.500 | 2.50 | 25.00 |"), "{md}");
        assert!(md.contains("| 4 | noisy | 2.00 | – | 2.00 | 20.00 |"), "{md}");
        assert!(dir.join("error-vs-time.svg").is_file());
        assert!(md.contains("| noisy | 20.00 / 0.5000 |"));
        assert!(
            md.contains("| ![noisy](oidn/eval/previews/noisy.png) | ![oidn](oidn/eval/previews/train/model.png) |"),
            "{md}"
        );
        assert!(md.contains("## Crops and differences"), "{md}");
        assert!(md.contains("| reference | ![reference](oidn/eval/r.png) | – | – |"), "{md}");
        assert!(
            md.contains("| noisy | ![noisy](oidn/eval/n.png) | ![noisy: pixels off](oidn/eval/nd.png) | 40.0 %"),
            "{md}"
        );
        assert!(
            md.contains(
                "| oidn | ![oidn](oidn/eval/m.png) | ![oidn: pixels off](oidn/eval/md.png) | 12.5 % > 3 %, 1.0 % > 10 % |"
            ),
            "{md}"
        );
        assert_eq!(claims[0].verdict, crate::sweep::claims::Verdict::NotMeasured);
        assert!(md.contains("not measured"));
        assert!(dir.join("curves.csv").is_file() && dir.join("test-loss.svg").is_file());
        let page = std::fs::read_to_string(dir.join("report.html")).unwrap();
        assert!(page.contains("<h1>Sweep <code>architecture</code> at scale <code>tiny</code></h1>"), "{page}");
        assert!(page.contains("<th>run</th><th>other flags</th>"));
        assert!(page.contains("<td><img src=\"oidn/eval/previews/train/model.png\" alt=\"oidn\""));
        assert!(!page.contains("|---"));
        let _ = std::fs::remove_dir_all(&dir);
    }
}
