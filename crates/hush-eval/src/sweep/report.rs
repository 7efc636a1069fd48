//! The aggregate of a sweep: `report.md` and `report.html` with a table per run, metrics per spp, previews,
//! crops and difference pictures, hush-eval's error-against-time view (`error_vs_time.csv`,
//! `error_vs_time_<metric>.svg`), the loss curves (`curves.csv`, `train_loss.svg`, `test_loss.svg`) and the
//! thesis's claims.

use std::collections::BTreeSet;
use std::path::Path;

use super::claims::{Claim, PSNR_MARGIN_DB, Verdict, claims};
use super::results::{EvalRow, RunResult, mean};
use super::{PlanScale, PlanSweep, flags};
use crate::doc::{Block, Document, Grid, Inline, Text, image, text};
use crate::report::write_file;
use crate::{Error, NOISY, Report, Result};

/// The loss-curve plots: file and what they show.
pub const LOSS_PLOTS: [(&str, &str); 2] = [("train_loss.svg", "training loss"), ("test_loss.svg", "test loss")];

fn opt(v: Option<f64>, digits: usize) -> String {
    v.filter(|x| x.is_finite()).map_or("–".into(), |x| format!("{x:.digits$}"))
}

fn code(s: impl Into<String>) -> Inline {
    Inline::Code(s.into())
}

fn plain(s: impl Into<String>) -> Inline {
    Inline::Text(s.into())
}

fn heading(s: &str) -> Block {
    Block::Heading(2, text(s))
}

fn create_dir(dir: &Path) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|source| Error::File {
        path: dir.to_path_buf(),
        action: "create the report folder",
        source,
    })
}

/// `report.md` and `report.html` of `doc` in `dir`.
fn write_document(doc: &Document, dir: &Path) -> Result<()> {
    write_file(&dir.join(Report::MARKDOWN_FILE), doc.to_markdown().as_bytes())?;
    write_file(&dir.join(Report::HTML_FILE), crate::html::document_to_html(doc, dir)?.as_bytes())
}

/// A path of a run's evaluation folder relative to the report's folder `dir`.
fn eval_path(r: &RunResult, dir: &Path, path: &str) -> String {
    let run = r.run.dir.strip_prefix(dir).unwrap_or(&r.run.dir);
    format!("{}/eval/{path}", run.display())
}

/// Writes the report of one sweep into `dir` and returns its claims.
pub fn write(sweep: &PlanSweep, scale: &PlanScale, results: &[RunResult], dir: &Path) -> Result<Vec<Claim>> {
    create_dir(dir)?;
    let done: Vec<&RunResult> = results.iter().filter(|r| r.done).collect();
    let mut doc = Document { title: format!("{} at {}", sweep.name, scale.name), blocks: Vec::new() };
    let title = vec![plain("Sweep "), code(&sweep.name), plain(" at scale "), code(&scale.name)];
    doc.push(Block::Heading(1, title));
    doc.push(Block::Paragraph(text(&sweep.description)));
    doc.push(Block::Paragraph(vec![
        plain(format!("{} of {} runs complete. Reproduce: ", done.len(), results.len())),
        code(format!("cargo xtask sweep {} --scale {}", sweep.name, scale.name)),
        plain("."),
    ]));
    let missing: Vec<&str> = results.iter().filter(|r| !r.done).map(|r| r.run.name.as_str()).collect();
    if !missing.is_empty() {
        doc.push(Block::Paragraph(text(format!("Not complete: {}.", missing.join(", ")))));
    }
    precondition_section(&mut doc, results);
    runs_section(&mut doc, &done);
    per_spp_section(&mut doc, &done);

    // Images: one test view at the lowest spp, noisy and every run's result.
    if let Some((view, spp)) =
        done.iter().flat_map(|r| r.model_rows()).map(|r| (r.view.clone(), r.spp)).min_by_key(|k| k.1)
    {
        let at = |r: &RunResult, noisy: bool| {
            let rows = if noisy { r.noisy_rows() } else { r.model_rows() };
            let row = rows.into_iter().find(|x| x.view == view && x.spp == spp)?;
            Some(eval_path(r, dir, row.preview.as_ref()?))
        };
        let cell = |alt: &str, p: Option<String>| p.map_or(text("–"), |p| image(alt, p));
        let mut head = vec![NOISY.to_string()];
        let mut cells = vec![cell(NOISY, done.iter().find_map(|r| at(r, true)))];
        for r in &done {
            head.push(r.run.name.clone());
            cells.push(cell(&r.run.name, at(r, false)));
        }
        doc.push(heading("Images"));
        let about = format!("{view} at {spp} spp (tonemapped previews of ");
        doc.push(Block::Paragraph(vec![plain(about), code("hush eval"), plain(").")]));
        let columns = head.len();
        doc.push(Block::Table(Grid { header: head, right: vec![false; columns], rows: vec![cells] }));
        crops_and_differences(&mut doc, &done, &view, spp, dir);
    }

    error_vs_time(&mut doc, &done, |r| r.run.name.clone(), dir)?;
    curves_section(&mut doc, &done, dir)?;

    let claims = claims(&sweep.name, results);
    claims_section(&mut doc, &claims);
    write_document(&doc, dir)?;
    Ok(claims)
}

/// Whether each complete run beats the noisy input at every test spp, the precondition of the quality
/// findings ([`super::claims`]).
fn precondition_section(doc: &mut Document, results: &[RunResult]) {
    let group = super::claims::Group(results);
    let mut names: Vec<&str> = results.iter().filter(|r| r.done).map(|r| r.run.group.as_str()).collect();
    names.sort_unstable();
    names.dedup();
    if names.is_empty() {
        return;
    }
    let short: Vec<String> = names.iter().filter_map(|g| group.undertrained(g)).collect();
    let line = if short.is_empty() {
        format!(
            "Precondition holds: every complete run ({} run groups) beats the noisy input at every test spp.",
            names.len()
        )
    } else {
        format!(
            "Precondition: {} of {} run groups do not beat the noisy input at every test spp; a quality finding is \
             inconclusive (undertrained) where none of the groups it compares does: {}.",
            short.len(),
            names.len(),
            short.join("; ")
        )
    };
    doc.push(Block::Paragraph(text(line)));
}

/// Per run: its flags, epochs, speed, losses and the test metrics of its model.
fn runs_section(doc: &mut Document, done: &[&RunResult]) {
    doc.push(heading("Runs"));
    doc.push(Block::Paragraph(vec![
        plain("Test metrics are means over the test views and spp of the final model ("),
        code("hush eval"),
        plain("); losses are those of "),
        code("hush train"),
        plain("'s "),
        code("metrics.csv"),
        plain(" (test loss on whole test images)."),
    ]));
    // The flags every run shares are shown once; the table shows those that differ.
    let mut common = done.first().map(|r| r.run.train.clone()).unwrap_or_default();
    common.retain(|pair| done.iter().all(|r| r.run.train.contains(pair)));
    doc.push(Block::Paragraph(vec![
        plain("Every run: "),
        code(format!("hush train {}", flags(&common).join(" "))),
        plain("."),
    ]));
    let header = [
        "run",
        "other flags",
        "epochs",
        "s/epoch",
        "train loss",
        "test loss",
        "best test loss (epoch)",
        "gap",
        "PSNR",
        "SSIM",
        "MAE",
        "relMSE",
        "denoise s",
    ];
    let mut g = Grid::new(header.map(String::from).to_vec(), (0..header.len()).map(|i| i > 1).collect());
    for r in done {
        let rows = r.model_rows();
        let m = |f: &dyn Fn(&EvalRow) -> Option<f64>| mean(rows.iter().filter_map(|x| f(x)));
        let last = r.last_tested();
        let other: Vec<(String, String)> =
            r.run.train.iter().filter(|(k, _)| !common.iter().any(|(c, _)| c == k)).cloned().collect();
        let cells = [
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
        ];
        let mut row = vec![text(&r.run.name), vec![code(flags(&other).join(" "))]];
        row.push(text(r.epochs.last().map_or(0, |e| e.epoch).to_string()));
        row.extend(cells.into_iter().map(text));
        g.rows.push(row);
    }
    doc.push(Block::Table(g));
}

/// PSNR / SSIM per spp: the noisy input, then each run.
fn per_spp_section(doc: &mut Document, done: &[&RunResult]) {
    let spps: BTreeSet<u64> = done.iter().flat_map(|r| r.model_rows()).map(|r| r.spp).collect();
    if spps.is_empty() {
        return;
    }
    doc.push(heading("PSNR (dB) / SSIM per spp"));
    doc.push(Block::Paragraph(text("Means over the test views.")));
    let cell = |rows: &[&EvalRow], spp: u64| {
        let at: Vec<_> = rows.iter().filter(|r| r.spp == spp).collect();
        text(format!(
            "{} / {}",
            opt(mean(at.iter().filter_map(|r| r.psnr)), 2),
            opt(mean(at.iter().filter_map(|r| r.ssim)), 4)
        ))
    };
    let mut header = vec!["method".to_string()];
    header.extend(spps.iter().map(|s| format!("{s} spp")));
    let mut g = Grid::new(header, (0..=spps.len()).map(|i| i > 0).collect());
    let mut line = |name: &str, rows: &[&EvalRow]| {
        let mut row = vec![text(name)];
        row.extend(spps.iter().map(|&s| cell(rows, s)));
        g.rows.push(row);
    };
    if let Some(first) = done.first() {
        line(NOISY, &first.noisy_rows());
    }
    for r in done {
        line(&r.run.name, &r.model_rows());
    }
    doc.push(Block::Table(g));
}

/// Per run, its model's crop of the window where the noisy input is worst and its difference picture against
/// the reference, as `hush eval` drew them (the thesis's figures 7.5–7.7 compare the losses this way); the
/// noisy input and the reference first. Nothing if no run has pictures.
fn crops_and_differences(doc: &mut Document, done: &[&RunResult], view: &str, spp: u64, dir: &Path) {
    let picture =
        |r: &RunResult, path: Option<&str>, alt: &str| path.map_or(text("–"), |p| image(alt, eval_path(r, dir, p)));
    let mut rows: Vec<Vec<Text>> = Vec::new();
    let reference = crate::REFERENCE;
    if let Some(r) = done.iter().find(|r| r.crop(view, spp, reference).is_some()) {
        rows.push(vec![text(reference), picture(r, r.crop(view, spp, reference), reference), text("–"), text("–")]);
    }
    let method_row = |r: &RunResult, name: &str, method: &str, crop: &str| {
        let (diff, shares) = r.difference(view, spp, method).unzip();
        vec![
            text(name),
            picture(r, Some(crop), name),
            picture(r, diff, &format!("{name}: pixels off")),
            text(shares.unwrap_or_else(|| "–".into())),
        ]
    };
    if let Some(r) = done.iter().find(|r| r.crop(view, spp, NOISY).is_some()) {
        let row = method_row(r, NOISY, NOISY, r.crop(view, spp, NOISY).expect("found"));
        rows.push(row);
    }
    let before = rows.len();
    for r in done {
        let Some(method) = r.model_rows().first().map(|m| m.method.clone()) else { continue };
        let Some(crop) = r.crop(view, spp, &method) else { continue };
        let row = method_row(r, &r.run.name, &method, crop);
        rows.push(row);
    }
    if rows.len() == before {
        return;
    }
    doc.push(heading("Crops and differences"));
    doc.push(Block::Paragraph(vec![
        plain(format!(
            "{view} at {spp} spp: each run's denoised crop of the window where the noisy input is worst, and its \
             pixels off the reference by more than 3 % (yellow) and 10 % (red) after the evaluation tonemap, as in the \
             thesis's figures 7.5–7.7 ("
        )),
        code("hush eval"),
        plain("'s pictures)."),
    ]));
    let header = ["run", "crop", "pixels off", "share > 3 %, > 10 %"].map(String::from).to_vec();
    doc.push(Block::Table(Grid { header, right: vec![false; 4], rows }));
}

/// The error-against-run-time table of `runs` (named by `label`), and hush-eval's error-against-time view of
/// them (its plots and CSV in `dir`, the noisy input's rows from the first run).
fn error_vs_time(
    doc: &mut Document,
    runs: &[&RunResult],
    label: impl Fn(&RunResult) -> String,
    dir: &Path,
) -> Result<()> {
    let Some(first) = runs.first() else { return Ok(()) };
    let spps: BTreeSet<u64> = runs.iter().flat_map(|r| r.model_rows()).map(|r| r.spp).collect();
    doc.push(heading("Error against run time"));
    doc.push(Block::Paragraph(text(
        "Per spp: the noisy render's seconds, then each model's render + denoise seconds and PSNR (means over the \
         test views).",
    )));
    let header = ["spp", "method", "render s", "denoise s", "total s", "PSNR (dB)"].map(String::from).to_vec();
    let mut g = Grid::new(header, vec![true, false, true, true, true, true]);
    let mut view = Report::default();
    view.rows.extend(first.noisy_rows().into_iter().map(|r| r.to_row(NOISY)));
    for run in std::iter::once(None).chain(runs.iter().map(|r| Some(*r))) {
        let name = run.map_or(NOISY.into(), &label);
        if let Some(r) = run {
            view.rows.extend(r.model_rows().into_iter().map(|x| x.to_row(&name)));
        }
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
            let cells = [spp.to_string(), name.clone(), opt(render, 2), den_cell, opt(total, 2), opt(psnr, 2)];
            g.rows.push(cells.into_iter().map(text).collect());
        }
    }
    doc.push(Block::Table(g));
    view.write_error_vs_time(dir)?;
    doc.blocks.extend(view.error_vs_time_blocks());
    Ok(())
}

/// The loss over epochs: `curves.csv`, the plots of the training and test losses, and a compact table.
fn curves_section(doc: &mut Document, done: &[&RunResult], dir: &Path) -> Result<()> {
    let mut csv = String::from("run,epoch,train_loss,test_loss,seconds\n");
    for r in done {
        for e in &r.epochs {
            let test = e.test_loss.map(|t| t.to_string()).unwrap_or_default();
            csv += &format!("{},{},{},{test},{}\n", r.run.name, e.epoch, e.train_loss, e.seconds);
        }
    }
    write_file(&dir.join("curves.csv"), csv.as_bytes())?;
    doc.push(heading("Loss over epochs"));
    doc.push(Block::Paragraph(vec![
        plain("All rows: "),
        code("curves.csv"),
        plain(". Epoch on x, the loss on a log scale on y."),
    ]));
    let train: Vec<Vec<(f64, f64)>> =
        done.iter().map(|r| r.epochs.iter().map(|e| (e.epoch as f64, e.train_loss)).collect()).collect();
    let test: Vec<Vec<(f64, f64)>> =
        done.iter().map(|r| r.epochs.iter().filter_map(|e| Some((e.epoch as f64, e.test_loss?))).collect()).collect();
    let mut plots = Vec::new();
    for ((file, title), series) in LOSS_PLOTS.into_iter().zip([train, test]) {
        if series.iter().all(Vec::is_empty) {
            continue;
        }
        let chart = hush_plot::Chart {
            title: format!("The {title} of each run"),
            x: hush_plot::Axis::linear("epoch"),
            y: hush_plot::Axis::log("loss (the run's training loss)"),
            series: done
                .iter()
                .zip(series)
                .enumerate()
                .map(|(i, (r, points))| hush_plot::Series::line(&r.run.name, crate::plot::series_color(i), points))
                .collect(),
        };
        write_file(&dir.join(file), chart.to_svg(720, 420).as_bytes())?;
        plots.extend(image(title, file));
    }
    if !plots.is_empty() {
        doc.push(Block::Paragraph(plots));
    }
    // A compact table of the test loss at up to 12 evaluated epochs.
    let epochs: BTreeSet<usize> =
        done.iter().flat_map(|r| r.epochs.iter().filter(|e| e.test_loss.is_some()).map(|e| e.epoch)).collect();
    let list: Vec<usize> = epochs.into_iter().collect();
    let Some(&last) = list.last() else { return Ok(()) };
    let mut picked: Vec<usize> = list.iter().copied().step_by(list.len().div_ceil(12)).collect();
    if picked.last() != Some(&last) {
        picked.push(last);
    }
    doc.push(Block::Paragraph(text("Test loss by epoch (train loss in parentheses):")));
    let mut header = vec!["run".to_string()];
    header.extend(picked.iter().map(|e| e.to_string()));
    let mut g = Grid::new(header, (0..=picked.len()).map(|i| i > 0).collect());
    for r in done {
        let mut row = vec![text(&r.run.name)];
        row.extend(picked.iter().map(|&p| match r.epochs.iter().find(|e| e.epoch == p) {
            Some(e) => text(format!("{} ({:.4})", opt(e.test_loss, 4), e.train_loss)),
            None => text("–"),
        }));
        g.rows.push(row);
    }
    doc.push(Block::Table(g));
    Ok(())
}

/// A verdict as a table cell: the decided ones in bold.
fn verdict(v: Verdict) -> Text {
    match v {
        Verdict::Reproduced => vec![Inline::Bold("reproduced".into())],
        Verdict::Refuted => vec![Inline::Bold("refuted".into())],
        Verdict::Inconclusive => text("inconclusive"),
        Verdict::Undertrained => text("inconclusive: undertrained"),
        Verdict::NotMeasured => text("not measured"),
    }
}

/// The claims table with the rule that decided them.
pub fn claims_section(doc: &mut Document, claims: &[Claim]) {
    if claims.is_empty() {
        return;
    }
    doc.push(heading("The thesis's findings"));
    doc.push(Block::Paragraph(vec![
        plain(format!(
            "Rule: runs A and B are compared on the rows of the same seed, test view and spp; \
         d̄ is the mean of the differences (positive = the thesis's direction), SE their standard error. \
         Reproduced when d̄ > 2·SE, refuted when d̄ < −2·SE, inconclusive otherwise or with fewer than 2 pairs. \
         \"Little difference\" claims: reproduced when |d̄| + 2·SE < {PSNR_MARGIN_DB} dB, refuted when |d̄| − 2·SE > \
         {PSNR_MARGIN_DB} dB. Rows of one view at several spp are not independent: SE is optimistic. Timing claims \
         compare wall seconds per epoch, which on a shared machine are only comparable under equal load (each run's "
        )),
        code("done.json"),
        plain(
            " records the load average). Precondition: a model group is worth using where each of its runs beats \
             the noisy input at every test spp (mean PSNR over the test views, spp by spp). A quality claim none of \
             whose compared groups is worth using is inconclusive: undertrained; where some are, it is decided and \
             names the runs that fell short where.",
        ),
    ]));
    let header = ["sweep", "thesis", "measured", "verdict"].map(String::from).to_vec();
    let rows = claims.iter().map(|c| vec![text(&c.sweep), text(&c.thesis), text(&c.measured), verdict(c.verdict)]);
    doc.push(Block::Table(Grid { header, right: vec![false; 4], rows: rows.collect() }));
}

/// The report of `all`: every model's error against run time and every sweep's claims, with links to the
/// sweeps' reports.
pub fn write_all(scale: &PlanScale, sweeps: &[(String, Vec<Claim>)], results: &[RunResult], dir: &Path) -> Result<()> {
    create_dir(dir)?;
    let mut doc = Document { title: format!("every sweep at {}", scale.name), blocks: Vec::new() };
    doc.push(Block::Heading(1, vec![plain("Every sweep at scale "), code(&scale.name)]));
    doc.push(Block::Paragraph(vec![
        plain("Dataset: "),
        code(format!("hush dataset {} {}", scale.scenes.join(" "), scale.dataset.join(" "))),
        plain("; every run also gets "),
        code(scale.train.join(" ")),
        plain(format!("; seeds {:?}.", scale.seeds)),
    ]));
    let links = sweeps.iter().map(|(name, _)| {
        vec![Inline::Link { text: name.clone(), href: format!("../../{name}/{}/report.md", scale.name) }]
    });
    doc.push(Block::List(links.collect()));
    let done: Vec<&RunResult> = results.iter().filter(|r| r.done).collect();
    error_vs_time(&mut doc, &done, |r| format!("{}/{}", r.run.sweep, r.run.name), dir)?;
    let all: Vec<Claim> = sweeps.iter().flat_map(|(_, c)| c.iter().cloned()).collect();
    claims_section(&mut doc, &all);
    write_document(&doc, dir)
}
