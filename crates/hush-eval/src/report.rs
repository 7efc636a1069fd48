//! Result tables: Markdown for people, `summary.json` for scripts.

use std::fmt::Write as _;
use std::path::Path;

use hush_dataset::write_atomic;
use serde::{Deserialize, Deserializer, Serialize};

use crate::{Error, Metrics, Result};

/// How the numbers in a report were computed; written at the top of `report.md` and into `summary.json`.
pub const CONVENTIONS: &str = "\
Metrics compare a test image against the reference of its view. \
PSNR, SSIM, MAE and MSE are computed on tonemapped images: x -> srgb(filmic(exposure * x)), the filmic curve \
being Hable's Uncharted 2 curve with Open Image Denoise's constants (training/color.py), values in [0, 1], \
with one exposure per view: OIDN's autoexposure of the reference (0.18 / geometric mean luminance). \
PSNR = 10 log10(1 / MSE) in dB (infinite for identical images; null in JSON). SSIM: Gaussian window 11 px, \
sigma 1.5, valid region, K1 0.01, K2 0.03, data range 1, mean over pixels and channels (the code of the SSIM \
training loss). relMSE is computed on the linear HDR images: mean of (x - ref)^2 / (ref^2 + 0.01). \
Seconds: median wall-clock denoising time (rendering time for renders), empty when not timed.";

/// One evaluated image.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Row {
    /// The view, e.g. `cbox_v0`.
    pub view: String,
    /// What produced the test image, e.g. `noisy`, `hush-unet`, `oidn-2.5.1`.
    pub method: String,
    /// Samples per pixel of the noisy input.
    pub spp: u32,
    /// dB; `f64::INFINITY` for a perfect match (null in JSON).
    #[serde(deserialize_with = "null_as_infinity")]
    pub psnr: f64,
    pub ssim: f64,
    pub mae: f64,
    pub mse: f64,
    pub rel_mse: f64,
    /// Median seconds, if timed.
    pub seconds: Option<f64>,
    /// A preview image, as a path relative to the report directory (used as a link in Markdown).
    pub preview: Option<String>,
}

impl Row {
    /// A row from computed metrics, without preview.
    pub fn new(view: &str, method: &str, spp: u32, metrics: &Metrics, seconds: Option<f64>) -> Row {
        Row {
            view: view.to_string(),
            method: method.to_string(),
            spp,
            psnr: metrics.psnr,
            ssim: metrics.ssim,
            mae: metrics.mae,
            mse: metrics.mse,
            rel_mse: metrics.rel_mse,
            seconds,
            preview: None,
        }
    }
}

fn null_as_infinity<'de, D: Deserializer<'de>>(d: D) -> std::result::Result<f64, D::Error> {
    Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::INFINITY))
}

/// An evaluation: rows in the order they were added, plus free-form notes (machine, threads, model, ...).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Report {
    pub rows: Vec<Row>,
    #[serde(default)]
    pub notes: Vec<String>,
}

#[derive(Serialize)]
struct Summary<'a> {
    conventions: &'a str,
    notes: &'a [String],
    rows: &'a [Row],
}

impl Report {
    pub const MARKDOWN_FILE: &'static str = "report.md";
    pub const JSON_FILE: &'static str = "summary.json";

    /// The rows as Markdown: the conventions, the notes, one table per view (in order of first appearance)
    /// and, with several views, a table of means per method and spp.
    pub fn to_markdown(&self) -> String {
        let mut md = String::from("# Denoising evaluation\n\n");
        let _ = writeln!(md, "{CONVENTIONS}\n");
        for note in &self.notes {
            let _ = writeln!(md, "- {note}");
        }
        if !self.notes.is_empty() {
            md.push('\n');
        }
        let mut views: Vec<&str> = Vec::new();
        for row in &self.rows {
            if !views.contains(&row.view.as_str()) {
                views.push(&row.view);
            }
        }
        let with_preview = self.rows.iter().any(|r| r.preview.is_some());
        for view in &views {
            let _ = writeln!(md, "## {}\n", escape(view));
            header(&mut md, "method", with_preview);
            for row in self.rows.iter().filter(|r| r.view == *view) {
                let preview = row.preview.as_deref().map(|p| format!("[png]({})", p.replace(' ', "%20")));
                line(&mut md, &escape(&row.method), row, preview.as_deref(), with_preview);
            }
            md.push('\n');
        }
        if views.len() > 1 {
            let _ = writeln!(md, "## Mean over {} views\n", views.len());
            header(&mut md, "method", false);
            for mean in self.means() {
                line(&mut md, &escape(&mean.method), &mean, None, false);
            }
            md.push('\n');
        }
        md
    }

    /// Mean of every metric per (method, spp) over the views, in order of first appearance; `view` is
    /// `"mean"`, `seconds` is the mean over the timed rows.
    pub fn means(&self) -> Vec<Row> {
        let mut keys: Vec<(&str, u32)> = Vec::new();
        for r in &self.rows {
            if !keys.contains(&(r.method.as_str(), r.spp)) {
                keys.push((&r.method, r.spp));
            }
        }
        keys.into_iter()
            .map(|(method, spp)| {
                let rows: Vec<&Row> = self.rows.iter().filter(|r| r.method == method && r.spp == spp).collect();
                let mean = |f: fn(&Row) -> f64| rows.iter().map(|r| f(r)).sum::<f64>() / rows.len() as f64;
                let timed: Vec<f64> = rows.iter().filter_map(|r| r.seconds).collect();
                Row {
                    view: "mean".into(),
                    method: method.into(),
                    spp,
                    psnr: mean(|r| r.psnr),
                    ssim: mean(|r| r.ssim),
                    mae: mean(|r| r.mae),
                    mse: mean(|r| r.mse),
                    rel_mse: mean(|r| r.rel_mse),
                    seconds: (!timed.is_empty()).then(|| timed.iter().sum::<f64>() / timed.len() as f64),
                    preview: None,
                }
            })
            .collect()
    }

    /// `summary.json`: `{ "conventions": ..., "notes": [...], "rows": [...] }`, pretty-printed.
    /// It reads back into a `Report` with `serde_json::from_str`.
    pub fn to_json(&self) -> String {
        let summary = Summary { conventions: CONVENTIONS, notes: &self.notes, rows: &self.rows };
        // Rows hold only strings and numbers (non-finite numbers become null): this cannot fail.
        let mut text = serde_json::to_string_pretty(&summary).expect("a report serializes to JSON");
        text.push('\n');
        text
    }

    /// Writes `report.md` and `summary.json` into `dir` (created if missing), each atomically.
    pub fn write(&self, dir: impl AsRef<Path>) -> Result<()> {
        let dir = dir.as_ref();
        std::fs::create_dir_all(dir).map_err(|source| Error::File {
            path: dir.to_path_buf(),
            action: "create the report directory",
            source,
        })?;
        for (name, text) in [(Self::MARKDOWN_FILE, self.to_markdown()), (Self::JSON_FILE, self.to_json())] {
            let path = dir.join(name);
            write_atomic(&path, |tmp| {
                std::fs::write(tmp, &text).map_err(|source| Error::File { path: path.clone(), action: "write", source })
            })?;
        }
        Ok(())
    }
}

fn header(md: &mut String, first: &str, with_preview: bool) {
    let _ = write!(md, "| {first} | spp | PSNR (dB) ↑ | SSIM ↑ | MAE ↓ | MSE ↓ | relMSE ↓ | seconds |");
    md.push_str(if with_preview { " preview |\n" } else { "\n" });
    md.push_str("|---|---:|---:|---:|---:|---:|---:|---:|");
    md.push_str(if with_preview { "---|\n" } else { "\n" });
}

fn line(md: &mut String, first: &str, r: &Row, preview: Option<&str>, with_preview: bool) {
    let psnr = if r.psnr.is_infinite() && r.psnr > 0.0 { "∞".to_string() } else { format!("{:.2}", r.psnr) };
    let seconds = r.seconds.map_or(String::new(), |s| format!("{s:.3}"));
    let _ = write!(
        md,
        "| {first} | {} | {psnr} | {:.4} | {:.4} | {:.3e} | {:.3e} | {seconds} |",
        r.spp, r.ssim, r.mae, r.mse, r.rel_mse
    );
    if with_preview {
        let _ = write!(md, " {} |", preview.unwrap_or(""));
    }
    md.push('\n');
}

fn escape(s: &str) -> String {
    s.replace('|', "\\|").replace('\n', " ")
}
