//! Result tables: `report.md` and a self-contained `report.html` for people, `summary.json` and
//! `error_vs_time.csv` for scripts, and the error-against-time plots.
//!
//! # `summary.json` (schema 4)
//!
//! Field names are stable; a change that breaks readers bumps `schema`.
//!
//! ```text
//! {
//!   "schema": 3,
//!   "conventions": "<how the numbers were computed>",
//!   "notes": ["<machine, threads, dataset, models>", ...],
//!   "skipped": [{"method": "bm3d", "reason": "...", "install": "<command>"}],
//!   "rows": [{
//!     "view": "cbox_v005", "method": "noisy" | "reference" | "<run>/<model>" | "<baseline>",
//!     "spp": 16,                 // spp of the noisy input (of the reference for "reference")
//!     "psnr": 31.2 | null,       // dB, null = infinite (identical images)
//!     "ssim": 0.93, "ms_ssim": 0.97 | null,   // null: a side below 176 px (MS-SSIM needs 5 scales)
//!     "mae": 0.01, "mse": 1e-4,  // on tonemapped images
//!     "rel_mse": 0.02,           // on linear HDR images
//!     "flip": 0.12,              // mean LDR-FLIP on the tonemapped images (null in rows of old reports)
//!     "render_seconds": 1.5 | null,   // rendering the noisy input at this spp (from the manifest)
//!     "denoise_seconds": 0.3 | null,  // warm median; null for noisy and reference
//!     "preview": "previews/....png" | null
//!   }],
//!   "tradeoff": [{                // one per (view, denoiser, spp, metric): see `crate::tradeoff`
//!     "view": ..., "method": ..., "spp": 16, "metric": "rel_mse" | "one_minus_ssim",
//!     "seconds": 1.8, "error": 0.01,           // render + denoise seconds, and the denoiser's error
//!     "raw_seconds": 7.2 | null,               // raw path tracing's time to the same error (interpolated)
//!     "raw_spp": 64.0 | null,                  // ... and its spp
//!     "time_percent": 25.0 | null,             // 100 · seconds / raw_seconds
//!     "raw_error_same_time": 0.05 | null,      // raw path tracing's error after `seconds`
//!     "status": "interpolated" | "below_ladder" | "above_ladder" | "no_ladder",
//!     "top_spp": 1024.0,                       // below_ladder only: the ladder's highest spp ...
//!     "top_time_percent": 3.4                  // ... and 100 · seconds / its render seconds (an upper bound)
//!   }],
//!   "tradeoff_overview": [{       // per (denoiser, spp, metric) over the views
//!     "method": ..., "spp": 16, "metric": ..., "views": 12, "interpolated": 9,
//!     "median_time_percent": 30.0 | null, "median_raw_spp": 55.0 | null,
//!     "median_error_ratio_same_time": 3.1 | null,
//!     "median_top_time_percent": 3.4, "top_spp": 1024.0   // only where views are below the ladder
//!   }],
//!   "figures": [{
//!     "title": ...,
//!     "kind": {"type": "crops" | "differences", "view": "cbox_v005", "spp": 16} | {"type": "other"},
//!     "images": [{"caption": ..., "path": "pictures/....png",
//!                 "method": "noisy" | ... ,                        // absent outside figures of methods
//!                 "marks": {"over_low": 0.12, "over_high": 0.01}}] // difference pictures only
//!   }],
//!   "viewers": [{                 // the image comparison of report.html, one per test view
//!     "view": "cbox_v005", "spp": 16, "width": 96, "height": 96,
//!     "exposure": 1.7,            // the evaluation tonemap's exposure (EV 0 in the page)
//!     "images": [{"method": "noisy", "path": "pictures/....rgbh.zz"}, ..., {"method": "reference", ...}]
//!   }]
//! }
//! ```
//!
//! Schema 4 added `viewers` (see [`crate::viewer`]); older summaries read back without them.
//! Schema 3 added the figures' `kind` and their images' `method` and `marks`; a schema-2 summary reads back
//! with every figure of kind `other`.
//!
//! `summary.json` reads back into a [`Report`] with `serde_json::from_str` (the derived fields are ignored).

use std::fmt::Write as _;
use std::path::Path;

use hush_dataset::write_atomic;
use serde::{Deserialize, Deserializer, Serialize};

use crate::doc::{Block, Grid, image, text};
use crate::pictures::Marks;
use crate::tradeoff::{self, Comparison, ErrorMetric};
use crate::viewer::Viewer;
use crate::{Error, Metrics, Result};

/// The version of `summary.json`'s layout.
pub const SCHEMA: u32 = 4;

/// How the numbers in a report were computed; written at the top of `report.md` and into `summary.json`.
pub const CONVENTIONS: &str = "\
Metrics compare a test image against the reference of its view. \
PSNR, SSIM, MS-SSIM, MAE and MSE are computed on tonemapped images: x -> srgb(filmic(exposure * x)), the filmic \
curve being Hable's Uncharted 2 curve with Open Image Denoise's constants (training/color.py), values in [0, 1], \
with one exposure per view: OIDN's autoexposure of the reference (0.18 / geometric mean luminance). \
PSNR = 10 log10(1 / MSE) in dB (infinite for identical images; null in JSON). SSIM: Gaussian window 11 px, \
sigma 1.5, valid region, K1 0.01, K2 0.03, data range 1, mean over pixels and channels (the code of the SSIM \
training loss). MS-SSIM: 5 scales with Wang's weights; it is left empty for images with a side below 176 px, \
which do not fit 5 scales. MAE and MSE are means over pixels and channels in [0, 1] (the thesis's tables used \
another scale). relMSE is computed on the linear HDR images: mean of (x - ref)^2 / (ref^2 + 0.01). \
The colour shift (color_shift in JSON) is, on the tonemapped images, the largest relative difference between a \
channel's image mean and the reference's: max over R, G, B of |mean(x) / mean(ref) - 1|. \
FLIP is LDR-FLIP (a port of NVIDIA's reference, flip-evaluator 1.7) on the same tonemapped images at 67 \
pixels per degree, the mean of its error map. Seconds: render seconds are the wall-clock time of rendering the noisy input \
at its spp, from the dataset's manifest; denoise seconds are the median wall-clock time of warm runs \
(empty for the noisy input). A denoiser's cost in the error-against-time comparison is render + denoise seconds \
at its input spp; raw path tracing's curve is the noisy images along the spp ladder, interpolated linearly in \
log(seconds)-log(error) between rungs and never extrapolated.";

/// One evaluated image.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Row {
    /// The view, e.g. `cbox_v000`.
    pub view: String,
    /// What produced the test image, e.g. `noisy`, `run/model`, `oidn`.
    pub method: String,
    /// Samples per pixel of the noisy input.
    pub spp: u32,
    /// dB; `f64::INFINITY` for a perfect match (null in JSON).
    #[serde(deserialize_with = "null_as_infinity")]
    pub psnr: f64,
    pub ssim: f64,
    /// `None` for images too small for 5 MS-SSIM scales.
    #[serde(default)]
    pub ms_ssim: Option<f64>,
    pub mae: f64,
    pub mse: f64,
    pub rel_mse: f64,
    /// Mean LDR-FLIP on the tonemapped images.
    #[serde(default)]
    pub flip: Option<f64>,
    /// [`Metrics::color_shift`]: the largest relative difference of a channel's mean from the reference's.
    #[serde(default)]
    pub color_shift: Option<f64>,
    /// Seconds to render the noisy input at `spp` (the reference's for `reference`), from the manifest.
    #[serde(default)]
    pub render_seconds: Option<f64>,
    /// Median seconds of warm denoising runs; `None` for the noisy input and the reference.
    #[serde(default)]
    pub denoise_seconds: Option<f64>,
    /// A preview image, as a path relative to the report directory (used as a link in Markdown).
    #[serde(default)]
    pub preview: Option<String>,
    /// Where the case has several renders of the noisy input (`hush dataset --test-repeats`): each metric above
    /// is the mean over them, and these are their PSNRs, the dataset's noisy render first (its image is the
    /// preview; render and denoise times are its own). Empty: one render.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub psnr_renders: Vec<f64>,
}

impl Row {
    /// A row from computed metrics, without times or preview.
    pub fn new(view: &str, method: &str, spp: u32, metrics: &Metrics) -> Row {
        Row {
            view: view.to_string(),
            method: method.to_string(),
            spp,
            psnr: metrics.psnr,
            ssim: metrics.ssim,
            ms_ssim: metrics.ms_ssim,
            mae: metrics.mae,
            mse: metrics.mse,
            rel_mse: metrics.rel_mse,
            flip: metrics.flip,
            color_shift: metrics.color_shift,
            render_seconds: None,
            denoise_seconds: None,
            preview: None,
            psnr_renders: Vec::new(),
        }
    }

    /// [`Row::new`] from the metrics of each render of the case: their means, and their PSNRs where there are
    /// several.
    pub fn of_renders(view: &str, method: &str, spp: u32, renders: &[Metrics]) -> Option<Row> {
        let mut row = Row::new(view, method, spp, &Metrics::mean(renders)?);
        if renders.len() > 1 {
            row.psnr_renders = renders.iter().map(|m| m.psnr).collect();
        }
        Some(row)
    }

    /// Render plus denoise seconds: what this image cost (`None` without a render time).
    pub fn total_seconds(&self) -> Option<f64> {
        Some(self.render_seconds? + self.denoise_seconds.unwrap_or(0.0))
    }

    /// Whether this row is raw path tracing (the noisy input).
    pub fn is_noisy(&self) -> bool {
        self.method == NOISY
    }

    /// Whether this row is a denoiser's output (neither the noisy input nor the reference).
    pub fn is_denoiser(&self) -> bool {
        self.method != NOISY && self.method != REFERENCE
    }
}

/// The method name of the noisy input (raw path tracing).
pub const NOISY: &str = "noisy";
/// The method name of the reference compared with itself.
pub const REFERENCE: &str = "reference";

fn null_as_infinity<'de, D: Deserializer<'de>>(d: D) -> std::result::Result<f64, D::Error> {
    Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::INFINITY))
}

/// A method that was asked for but could not run, with the command that installs what it needs.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Skipped {
    pub method: String,
    pub reason: String,
    /// The command that installs the method, if there is one.
    pub install: Option<String>,
}

/// One captioned image of a figure; `path` is relative to the report directory.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FigureImage {
    pub caption: String,
    pub path: String,
    /// The method the image shows (`noisy`, `reference`, a model, a baseline), in figures of methods.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub method: Option<String>,
    /// The shares of pixels a difference picture marks.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub marks: Option<Marks>,
}

impl FigureImage {
    /// An image that belongs to no method.
    pub fn new(caption: impl Into<String>, path: impl Into<String>) -> FigureImage {
        FigureImage { caption: caption.into(), path: path.into(), method: None, marks: None }
    }
}

/// What a figure shows, so that readers of `summary.json` find it without reading its title.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum FigureKind {
    /// Per method (and the reference), the crop of the window where the noisy input is worst.
    Crops { view: String, spp: u32 },
    /// Per method, its difference picture against the reference, with the shares of marked pixels.
    Differences { view: String, spp: u32 },
    /// Anything else (and every figure of a schema-2 summary).
    #[default]
    Other,
}

/// A row of captioned images under a title (e.g. the crops of one view).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Figure {
    pub title: String,
    #[serde(default)]
    pub kind: FigureKind,
    pub images: Vec<FigureImage>,
    /// A sentence under the images.
    #[serde(default)]
    pub note: String,
}

/// An evaluation: rows in the order they were added, notes (machine, threads, model, ...), skipped methods
/// and figures (pictures written by the caller into the report directory).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Report {
    pub rows: Vec<Row>,
    #[serde(default)]
    pub notes: Vec<String>,
    #[serde(default)]
    pub skipped: Vec<Skipped>,
    #[serde(default)]
    pub figures: Vec<Figure>,
    /// The image comparisons of `report.html`, one per view (files written by [`Viewer::write`]).
    #[serde(default)]
    pub viewers: Vec<Viewer>,
}

#[derive(Serialize)]
struct Summary<'a> {
    schema: u32,
    conventions: &'a str,
    notes: &'a [String],
    skipped: &'a [Skipped],
    rows: &'a [Row],
    tradeoff: &'a [Comparison],
    tradeoff_overview: &'a [tradeoff::Overview],
    figures: &'a [Figure],
    viewers: &'a [Viewer],
}

impl Report {
    pub const MARKDOWN_FILE: &'static str = "report.md";
    pub const HTML_FILE: &'static str = "report.html";
    pub const JSON_FILE: &'static str = "summary.json";
    pub const CSV_FILE: &'static str = "error_vs_time.csv";

    /// The plot file of one error metric, e.g. `error_vs_time_rel_mse.svg`.
    pub fn plot_file(metric: ErrorMetric) -> String {
        format!("error_vs_time_{}.svg", metric.key())
    }

    /// Views in order of first appearance.
    pub fn views(&self) -> Vec<&str> {
        in_order(self.rows.iter().map(|r| r.view.as_str()))
    }

    /// Methods in order of first appearance.
    pub fn methods(&self) -> Vec<&str> {
        in_order(self.rows.iter().map(|r| r.method.as_str()))
    }

    /// Every denoiser compared with raw path tracing, per view, spp and error metric.
    pub fn tradeoff(&self) -> Vec<Comparison> {
        tradeoff::compare_to_raw(&self.rows)
    }

    /// What the report compares, in one sentence: the views, the methods, the input spp and the references'.
    pub fn compared(&self) -> String {
        let views = self.views();
        let shown: Vec<&str> = views.iter().take(6).copied().collect();
        let more =
            if views.len() > shown.len() { format!(" and {} more", views.len() - shown.len()) } else { String::new() };
        let methods: Vec<&str> = self.methods().into_iter().filter(|m| *m != NOISY && *m != REFERENCE).collect();
        let mut spp: Vec<u32> = self.rows.iter().filter(|r| r.is_noisy()).map(|r| r.spp).collect();
        spp.sort_unstable();
        spp.dedup();
        let mut ref_spp: Vec<u32> = self.rows.iter().filter(|r| r.method == REFERENCE).map(|r| r.spp).collect();
        ref_spp.sort_unstable();
        ref_spp.dedup();
        let list = |v: &[u32]| v.iter().map(u32::to_string).collect::<Vec<_>>().join(", ");
        format!(
            "{} test view{} ({}{more}); the noisy input at {} spp{}; against references of {} spp.",
            views.len(),
            if views.len() == 1 { "" } else { "s" },
            shown.join(", "),
            list(&spp),
            if methods.is_empty() { String::new() } else { format!(" and denoised by {}", methods.join(", ")) },
            list(&ref_spp)
        )
    }

    /// The headline of each denoiser at the lowest spp it was given: how much raw path tracing it is worth
    /// in relMSE (the median over the views of "reaches raw N spp's error in X % of its time"), and on how many
    /// views raw path tracing does not reach its error within the ladder (or beats it at the lowest rung).
    pub fn headlines(&self) -> Vec<String> {
        let Some(spp) = self.table_spp() else { return Vec::new() };
        let comparisons: Vec<Comparison> =
            self.tradeoff().into_iter().filter(|c| c.spp == spp && c.metric == ErrorMetric::RelMse).collect();
        let overview = tradeoff::overview(&comparisons);
        overview
            .iter()
            .map(|o| {
                let count = |status: &str| comparisons.iter().filter(|c| c.method == o.method && c.status == status).count();
                let mut s = match (o.median_raw_spp, o.median_time_percent) {
                    (Some(raw), Some(pct)) => {
                        let over =
                            if o.views == 1 { String::new() } else { format!(", the median over {} views", o.interpolated) };
                        format!(
                            "{} from {spp} spp reaches raw path tracing's relMSE at {raw:.0} spp in {pct:.1} % of its time{over}",
                            o.method
                        )
                    }
                    _ => format!("{} from {spp} spp", o.method),
                };
                let (below, above) = (count("below_ladder"), count("above_ladder"));
                if below > 0 {
                    s += &format!("; on {below} of {} views its relMSE is below raw path tracing's at the ladder's highest spp", o.views);
                    if let (Some(top), Some(pct)) = (o.top_spp, o.median_top_time_percent) {
                        let median = if below == 1 { "" } else { "a median " };
                        s += &format!(" ({top:.0}), in {median}{pct:.1} % of that render's time");
                    }
                    s += " (not extrapolated)";
                }
                if above > 0 {
                    s += &format!("; on {above} of {} views raw path tracing is better already at its lowest spp", o.views);
                }
                s + "."
            })
            .collect()
    }

    /// The spp of the thesis-style tables and the pictures: the lowest spp a denoiser was evaluated at.
    pub fn table_spp(&self) -> Option<u32> {
        self.rows.iter().filter(|r| r.is_denoiser()).map(|r| r.spp).min()
    }

    /// The report as Markdown: the conventions, notes, skipped methods, the thesis-style tables (Tables
    /// 8.1–8.3), every row per view, means over views, the error-against-time summary and plots, and figures.
    pub fn to_markdown(&self) -> String {
        let mut md = String::from("# Denoising evaluation\n\n");
        let _ = writeln!(md, "{}\n", md_text(&self.compared()));
        for line in self.headlines() {
            let _ = writeln!(md, "- **{}**", md_text(&line));
        }
        if !self.viewers.is_empty() {
            let _ = writeln!(
                md,
                "\nOpen `report.html` beside this file for the images: flip between the methods, split, zoom and \
                 change the exposure."
            );
        }
        md.push('\n');
        let _ = writeln!(md, "{CONVENTIONS}\n");
        for note in &self.notes {
            let _ = writeln!(md, "- {}", md_text(note));
        }
        if !self.notes.is_empty() {
            md.push('\n');
        }
        if !self.skipped.is_empty() {
            md.push_str("## Skipped methods\n\n");
            for s in &self.skipped {
                let install = s.install.as_deref().map(|c| format!(" Install: `{c}`")).unwrap_or_default();
                let _ = writeln!(md, "- {}: skipped: {}.{install}", md_text(&s.method), md_text(&s.reason));
            }
            md.push('\n');
        }
        for (title, table) in self.tables() {
            let _ = writeln!(md, "## {}\n", md_text(&title));
            md.push_str(&table.to_markdown());
            md.push('\n');
        }
        md.push_str("## Error against run time\n\n");
        md.push_str(TRADEOFF_INTRO);
        md.push_str("\n\n");
        for metric in ErrorMetric::ALL {
            let _ = writeln!(md, "![{} against seconds]({})\n", metric.label(), Self::plot_file(metric));
        }
        if let Some(table) = self.overview_table() {
            md.push_str("\nOver the views:\n\n");
            md.push_str(&table.to_markdown());
            md.push_str("\nPer view:\n\n");
        }
        let comparisons = self.tradeoff();
        if comparisons.is_empty() {
            md.push_str("\nNo denoiser to compare with raw path tracing.\n");
        }
        for c in &comparisons {
            let _ = writeln!(md, "- {}", md_text(&c.sentence()));
        }
        md.push('\n');
        for figure in &self.figures {
            let _ = writeln!(md, "## {}\n", md_text(&figure.title));
            md.push('|');
            for image in &figure.images {
                let _ = write!(md, " {} |", md_text(&image.caption));
            }
            md.push_str("\n|");
            md.push_str(&"---|".repeat(figure.images.len()));
            md.push_str("\n|");
            for image in &figure.images {
                let _ = write!(md, " ![]({}) |", image.path.replace(' ', "%20"));
            }
            md.push_str("\n\n");
            if !figure.note.is_empty() {
                let _ = writeln!(md, "{}\n", md_text(&figure.note));
            }
        }
        md
    }

    /// Every table of the report with its title: [`Self::thesis_tables`], then [`Self::detail_tables`].
    pub fn tables(&self) -> Vec<(String, Table)> {
        let mut tables = self.thesis_tables();
        tables.extend(self.detail_tables());
        tables
    }

    /// Per view the thesis-style table at [`Self::table_spp`].
    pub fn thesis_tables(&self) -> Vec<(String, Table)> {
        let mut tables = Vec::new();
        let views = self.views();
        if let Some(spp) = self.table_spp() {
            for view in &views {
                let rows = self.thesis_rows(view, spp);
                if !rows.is_empty() {
                    tables
                        .push((format!("{view} at {spp} spp (as the thesis's Tables 8.1–8.3)"), Table::thesis(&rows)));
                }
            }
        }
        tables
    }

    /// Per view all rows, and with several views the means.
    pub fn detail_tables(&self) -> Vec<(String, Table)> {
        let mut tables = Vec::new();
        let views = self.views();
        for view in &views {
            let rows: Vec<&Row> = self.rows.iter().filter(|r| r.view == *view).collect();
            tables.push((format!("{view}: all rows"), Table::rows(&rows)));
        }
        if views.len() > 1 {
            let means = self.means();
            tables.push((format!("Mean over {} views", views.len()), Table::rows(&means.iter().collect::<Vec<_>>())));
        }
        tables
    }

    /// The error-against-time comparisons per denoiser, spp and metric over the views (see
    /// [`tradeoff::overview`]); `None` without a denoiser.
    pub fn overview_table(&self) -> Option<Table> {
        let overview = tradeoff::overview(&self.tradeoff());
        (!overview.is_empty()).then(|| Table::overview(&overview))
    }

    /// The rows of one view at one spp in the thesis's table order: the noisy input, then each method.
    pub fn thesis_rows(&self, view: &str, spp: u32) -> Vec<&Row> {
        self.rows.iter().filter(|r| r.view == view && r.spp == spp && r.method != REFERENCE).collect()
    }

    /// The error-against-time section for a document: what it shows, the plots of [`Self::write_error_vs_time`]
    /// (each with its legend) and the comparisons over the views.
    pub fn error_vs_time_blocks(&self) -> Vec<Block> {
        let mut blocks = vec![Block::Paragraph(text(TRADEOFF_INTRO))];
        let plots = ErrorMetric::ALL.map(|m| image(format!("{} against seconds", m.label()), Self::plot_file(m)));
        blocks.push(Block::Paragraph(plots.concat()));
        if let Some(table) = self.overview_table() {
            blocks.push(Block::Paragraph(text("Over the views:")));
            blocks.push(Block::Table(Grid::of_table(&table)));
        }
        blocks
    }

    /// Writes `error_vs_time.csv` and one plot per error metric into `dir` (which must exist), atomically.
    pub fn write_error_vs_time(&self, dir: &Path) -> Result<()> {
        write_file(&dir.join(Self::CSV_FILE), tradeoff::to_csv(&self.rows).as_bytes())?;
        let methods: Vec<&str> = self.methods().into_iter().filter(|m| *m != REFERENCE).collect();
        for metric in ErrorMetric::ALL {
            let svg = crate::plot::plot_error_vs_time(&self.rows, &methods, metric, 800, 560);
            write_file(&dir.join(Self::plot_file(metric)), svg.as_bytes())?;
        }
        Ok(())
    }

    /// Mean of every metric per (method, spp) over the views, in order of first appearance; `view` is
    /// `"mean"`; optional values are averaged over the rows that have them.
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
                let mean_some = |f: fn(&Row) -> Option<f64>| {
                    let some: Vec<f64> = rows.iter().filter_map(|r| f(r)).collect();
                    (!some.is_empty()).then(|| some.iter().sum::<f64>() / some.len() as f64)
                };
                Row {
                    view: "mean".into(),
                    method: method.into(),
                    spp,
                    psnr: mean(|r| r.psnr),
                    ssim: mean(|r| r.ssim),
                    ms_ssim: mean_some(|r| r.ms_ssim),
                    mae: mean(|r| r.mae),
                    mse: mean(|r| r.mse),
                    rel_mse: mean(|r| r.rel_mse),
                    flip: mean_some(|r| r.flip),
                    color_shift: mean_some(|r| r.color_shift),
                    render_seconds: mean_some(|r| r.render_seconds),
                    denoise_seconds: mean_some(|r| r.denoise_seconds),
                    preview: None,
                    psnr_renders: Vec::new(),
                }
            })
            .collect()
    }

    /// `summary.json` (see the module docs for its schema), pretty-printed.
    pub fn to_json(&self) -> String {
        let tradeoff = self.tradeoff();
        let overview = tradeoff::overview(&tradeoff);
        let summary = Summary {
            schema: SCHEMA,
            conventions: CONVENTIONS,
            notes: &self.notes,
            skipped: &self.skipped,
            rows: &self.rows,
            tradeoff: &tradeoff,
            tradeoff_overview: &overview,
            figures: &self.figures,
            viewers: &self.viewers,
        };
        // Only strings and numbers (non-finite numbers become null): this cannot fail.
        let mut text = serde_json::to_string_pretty(&summary).expect("a report serializes to JSON");
        text.push('\n');
        text
    }

    /// Writes into `dir` (created if missing), each file atomically: `error_vs_time.csv`, one plot per error
    /// metric, `summary.json`, `report.md` and `report.html` (which inlines every image the report refers to,
    /// so the figures' files must already be in `dir`).
    pub fn write(&self, dir: impl AsRef<Path>) -> Result<()> {
        let dir = dir.as_ref();
        std::fs::create_dir_all(dir).map_err(|source| Error::File {
            path: dir.to_path_buf(),
            action: "create the report directory",
            source,
        })?;
        self.write_error_vs_time(dir)?;
        write_file(&dir.join(Self::JSON_FILE), self.to_json().as_bytes())?;
        write_file(&dir.join(Self::MARKDOWN_FILE), self.to_markdown().as_bytes())?;
        let html = crate::html::to_html(self, dir)?;
        write_file(&dir.join(Self::HTML_FILE), html.as_bytes())
    }
}

/// What the error-against-time section shows.
pub const TRADEOFF_INTRO: &str = "\
For each test view, error against seconds on log-log axes: raw path tracing along the spp ladder (render \
seconds), and each denoiser at each input spp (render seconds of its input + denoise seconds). A denoiser \"reaches the error of raw N spp in X % of its time\" when raw path tracing needs \
N spp (interpolated) to reach the denoiser's error and the denoiser costs X % of that time; equal time gives raw \
path tracing's error after the denoiser's seconds.";

/// A path as a report shows it, without the machine's folders: relative to the working directory when it
/// lies under it, else its last three components after `…/`.
pub fn shown_path(path: &Path) -> String {
    let absolute = std::path::absolute(path).unwrap_or_else(|_| path.to_path_buf());
    if let Ok(cwd) = std::env::current_dir()
        && let Ok(rel) = absolute.strip_prefix(&cwd)
    {
        return if rel.as_os_str().is_empty() { ".".into() } else { rel.display().to_string() };
    }
    let parts: Vec<_> = absolute.components().rev().take(3).collect();
    let tail: std::path::PathBuf = parts.into_iter().rev().collect();
    format!("…/{}", tail.display())
}

/// Writes bytes to `path` atomically.
pub(crate) fn write_file(path: &Path, bytes: &[u8]) -> Result<()> {
    write_atomic(path, |tmp| {
        std::fs::write(tmp, bytes).map_err(|source| Error::File { path: path.to_path_buf(), action: "write", source })
    })
}

/// `∞` for an infinite PSNR, else two decimals.
pub(crate) fn psnr_text(psnr: f64) -> String {
    if psnr.is_infinite() && psnr > 0.0 { "∞".to_string() } else { format!("{psnr:.2}") }
}

/// An optional number with `digits` decimals, empty for `None`.
pub(crate) fn opt(v: Option<f64>, digits: usize) -> String {
    v.map_or(String::new(), |v| format!("{v:.digits$}"))
}

/// A table of text cells; the first column is a name, the others numbers (right-aligned).
#[derive(Clone, Debug, PartialEq)]
pub struct Table {
    pub header: Vec<&'static str>,
    pub rows: Vec<Vec<String>>,
    /// A relative path per row (a preview), shown as a link in Markdown only.
    pub links: Vec<Option<String>>,
}

impl Table {
    /// The thesis's Tables 8.1–8.3: method, denoising time, MAE, MSE, PSNR, SSIM.
    fn thesis(rows: &[&Row]) -> Table {
        Table {
            header: vec!["method", "denoising time (s)", "MAE ↓", "MSE ↓", "PSNR (dB) ↑", "SSIM ↑"],
            rows: rows
                .iter()
                .map(|r| {
                    vec![
                        r.method.clone(),
                        opt(r.denoise_seconds, 3),
                        format!("{:.4}", r.mae),
                        format!("{:.3e}", r.mse),
                        psnr_text(r.psnr),
                        format!("{:.4}", r.ssim),
                    ]
                })
                .collect(),
            links: vec![None; rows.len()],
        }
    }

    /// Per denoiser, spp and error metric over the views: how often raw path tracing reaches its error and
    /// the medians of the equal-error and equal-time comparisons.
    fn overview(rows: &[tradeoff::Overview]) -> Table {
        Table {
            header: vec![
                "method",
                "spp",
                "error",
                "views reached / compared",
                "median % of raw time",
                "median raw spp",
                "median raw error ÷ its error at equal time",
            ],
            rows: rows
                .iter()
                .map(|o| {
                    vec![
                        o.method.clone(),
                        o.spp.to_string(),
                        o.metric.label().to_string(),
                        format!("{} / {}", o.interpolated, o.views),
                        opt(o.median_time_percent, 1),
                        opt(o.median_raw_spp, 1),
                        opt(o.median_error_ratio_same_time, 2),
                    ]
                })
                .collect(),
            links: vec![None; rows.len()],
        }
    }

    /// Every metric and time of each row.
    fn rows(rows: &[&Row]) -> Table {
        Table {
            header: vec![
                "method",
                "spp",
                "PSNR (dB) ↑",
                "SSIM ↑",
                "MS-SSIM ↑",
                "MAE ↓",
                "MSE ↓",
                "relMSE ↓",
                "FLIP ↓",
                "render s",
                "denoise s",
            ],
            rows: rows
                .iter()
                .map(|r| {
                    vec![
                        r.method.clone(),
                        r.spp.to_string(),
                        psnr_text(r.psnr),
                        format!("{:.4}", r.ssim),
                        opt(r.ms_ssim, 4),
                        format!("{:.4}", r.mae),
                        format!("{:.3e}", r.mse),
                        format!("{:.3e}", r.rel_mse),
                        opt(r.flip, 4),
                        opt(r.render_seconds, 3),
                        opt(r.denoise_seconds, 3),
                    ]
                })
                .collect(),
            links: rows.iter().map(|r| r.preview.clone()).collect(),
        }
    }

    /// A Markdown table, with a `preview` column when any row has a link.
    pub fn to_markdown(&self) -> String {
        let with_links = self.links.iter().any(Option::is_some);
        let mut md = String::from("|");
        for h in &self.header {
            let _ = write!(md, " {h} |");
        }
        md.push_str(if with_links { " preview |\n|---|" } else { "\n|---|" });
        md.push_str(&"---:|".repeat(self.header.len() - 1));
        md.push_str(if with_links { "---|\n" } else { "\n" });
        for (row, link) in self.rows.iter().zip(&self.links) {
            md.push('|');
            for cell in row {
                let _ = write!(md, " {} |", md_text(cell));
            }
            if with_links {
                let link = link.as_deref().map(|p| format!("[png]({})", p.replace(' ', "%20")));
                let _ = write!(md, " {} |", link.unwrap_or_default());
            }
            md.push('\n');
        }
        md
    }
}

/// The distinct items in order of first appearance.
pub(crate) fn in_order<'a>(items: impl Iterator<Item = &'a str>) -> Vec<&'a str> {
    let mut out: Vec<&str> = Vec::new();
    for item in items {
        if !out.contains(&item) {
            out.push(item);
        }
    }
    out
}

/// Text for a Markdown table cell or list item: `|` escaped, line breaks flattened.
pub(crate) fn md_text(s: &str) -> String {
    s.replace('|', "\\|").replace(['\n', '\r'], " ")
}
