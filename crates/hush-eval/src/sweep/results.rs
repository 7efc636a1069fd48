//! What a run left behind: `train/metrics.csv` (loss per epoch, read by hush-train's own reader) and
//! `eval/summary.json` (deserialized: schema 1 with `seconds`, schemas 2 to 4 with `render_seconds` and
//! `denoise_seconds`; the crops and difference pictures found by their figure's [`FigureKind`]).

use std::path::Path;

use hush_train::{EpochRow, parse_metrics_csv};
use serde::Deserialize;

use super::PlanRun;
use crate::pictures::Marks;
use crate::{Error, Figure, FigureImage, FigureKind, NOISY, REFERENCE, Result, Row};

/// One row of `eval/summary.json`, of any schema: every metric optional (rows of old reports lack some).
#[derive(Clone, Debug, Default, PartialEq, Deserialize)]
#[serde(default)]
pub struct EvalRow {
    pub view: String,
    pub method: String,
    pub spp: u64,
    /// `None` also for an infinite PSNR (null in JSON).
    pub psnr: Option<f64>,
    pub ssim: Option<f64>,
    pub mae: Option<f64>,
    pub rel_mse: Option<f64>,
    /// The largest relative difference of a channel's display-image mean from the reference's.
    pub color_shift: Option<f64>,
    /// Render seconds of a noisy image or a reference.
    pub render_seconds: Option<f64>,
    /// Denoise seconds of a model.
    pub denoise_seconds: Option<f64>,
    /// The PNG preview, relative to the evaluation folder.
    pub preview: Option<String>,
    /// Schema 1's one time (the render's for the noisy input and the reference, else the denoiser's),
    /// moved into `render_seconds` or `denoise_seconds` when read: `None` after.
    pub seconds: Option<f64>,
}

impl EvalRow {
    /// Moves schema 1's `seconds` into `render_seconds` or `denoise_seconds`.
    fn normalized(mut self) -> EvalRow {
        if let Some(s) = self.seconds.take() {
            if matches!(self.method.as_str(), NOISY | REFERENCE) {
                self.render_seconds = self.render_seconds.or(Some(s));
            } else {
                self.denoise_seconds = self.denoise_seconds.or(Some(s));
            }
        }
        self
    }

    /// As a row of hush-eval's error-against-time view, named `method` (a metric it lacks is NaN, which
    /// the view leaves out).
    pub fn to_row(&self, method: &str) -> Row {
        let nan = |v: Option<f64>| v.unwrap_or(f64::NAN);
        Row {
            view: self.view.clone(),
            method: method.to_string(),
            spp: u32::try_from(self.spp).unwrap_or(u32::MAX),
            psnr: nan(self.psnr),
            ssim: nan(self.ssim),
            ms_ssim: None,
            mae: nan(self.mae),
            mse: f64::NAN,
            rel_mse: nan(self.rel_mse),
            flip: None,
            color_shift: self.color_shift,
            render_seconds: self.render_seconds,
            denoise_seconds: self.denoise_seconds,
            preview: None,
            psnr_renders: Vec::new(),
        }
    }
}

/// The part of `eval/summary.json` the sweep reads.
#[derive(Debug, Default, Deserialize)]
struct EvalSummary {
    #[serde(default)]
    rows: Vec<EvalRow>,
    #[serde(default)]
    figures: Vec<Figure>,
}

/// One image of `eval/summary.json`'s figures with the figure's kind.
#[derive(Clone, Debug, PartialEq)]
pub struct Picture {
    pub kind: FigureKind,
    pub image: FigureImage,
}

/// A run and its results (empty where a file is missing).
#[derive(Clone, Debug)]
pub struct RunResult {
    pub run: PlanRun,
    pub done: bool,
    pub epochs: Vec<EpochRow>,
    pub eval: Vec<EvalRow>,
    pub pictures: Vec<Picture>,
}

/// The rows of an evaluation summary (`summary.json`, any schema).
pub fn parse_eval(summary: &str, file: &Path) -> Result<Vec<EvalRow>> {
    Ok(parse_summary(summary, file)?.rows)
}

/// The images of the figures of an evaluation summary, with their figure's kind.
pub fn parse_pictures(summary: &str, file: &Path) -> Result<Vec<Picture>> {
    Ok(flatten(parse_summary(summary, file)?.figures))
}

fn parse_summary(text: &str, file: &Path) -> Result<EvalSummary> {
    let mut s: EvalSummary =
        serde_json::from_str(text).map_err(|source| Error::ReadJson { path: file.to_path_buf(), source })?;
    s.rows = s.rows.into_iter().map(EvalRow::normalized).collect();
    Ok(s)
}

fn flatten(figures: Vec<Figure>) -> Vec<Picture> {
    figures
        .into_iter()
        .flat_map(|f| {
            let kind = f.kind;
            f.images.into_iter().map(move |image| Picture { kind: kind.clone(), image })
        })
        .collect()
}

/// A file's text, or `None` when it does not exist.
fn read_if_present(path: &Path) -> Result<Option<String>> {
    match std::fs::read_to_string(path) {
        Ok(text) => Ok(Some(text)),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
        Err(source) => Err(Error::File { path: path.to_path_buf(), action: "read", source }),
    }
}

impl RunResult {
    /// Reads the run's folder; missing files leave their part empty, a summary that does not parse is an
    /// error naming it.
    pub fn load(run: &PlanRun) -> Result<RunResult> {
        let dir = &run.dir;
        let epochs = parse_metrics_csv(&read_if_present(&dir.join("train/metrics.csv"))?.unwrap_or_default());
        let file = dir.join("eval/summary.json");
        let summary = match read_if_present(&file)? {
            Some(text) => parse_summary(&text, &file)?,
            None => EvalSummary::default(),
        };
        Ok(RunResult {
            run: run.clone(),
            done: dir.join("done.json").is_file(),
            epochs,
            eval: summary.rows,
            pictures: flatten(summary.figures),
        })
    }

    fn picture(&self, want: &FigureKind, method: &str) -> Option<&FigureImage> {
        let p = self.pictures.iter().find(|p| p.kind == *want && p.image.method.as_deref() == Some(method))?;
        Some(&p.image)
    }

    /// `method`'s crop of the worst window of `view` at `spp` (`hush eval`'s figure of kind
    /// [`FigureKind::Crops`]), relative to the evaluation folder.
    pub fn crop(&self, view: &str, spp: u64, method: &str) -> Option<&str> {
        let kind = FigureKind::Crops { view: view.to_string(), spp: u32::try_from(spp).ok()? };
        self.picture(&kind, method).map(|i| i.path.as_str())
    }

    /// `method`'s difference picture of `view` at `spp` and the shares of pixels it marks, as
    /// `12.5 % > 3 %, 1.0 % > 10 %`.
    pub fn difference(&self, view: &str, spp: u64, method: &str) -> Option<(&str, String)> {
        let kind = FigureKind::Differences { view: view.to_string(), spp: u32::try_from(spp).ok()? };
        let image = self.picture(&kind, method)?;
        let shares = image.marks.map_or("–".to_string(), |m: Marks| {
            format!("{:.1} % > 3 %, {:.1} % > 10 %", 100.0 * m.over_low, 100.0 * m.over_high)
        });
        Some((image.path.as_str(), shares))
    }

    /// The rows of the trained model (the method that is neither `noisy` nor `reference`, preferring
    /// `train/model`).
    pub fn model_rows(&self) -> Vec<&EvalRow> {
        let is_model = |m: &str| m == "train/model";
        let any_model = |m: &str| !matches!(m, NOISY | REFERENCE);
        let pick: &dyn Fn(&str) -> bool =
            if self.eval.iter().any(|r| is_model(&r.method)) { &is_model } else { &any_model };
        self.eval.iter().filter(|r| pick(&r.method)).collect()
    }

    pub fn noisy_rows(&self) -> Vec<&EvalRow> {
        self.eval.iter().filter(|r| r.method == NOISY).collect()
    }

    /// Seconds per epoch: the training's wall time over its epochs (a resumed part restarts the clock).
    pub fn seconds_per_epoch(&self) -> Option<f64> {
        let mut total = 0.0;
        let mut last = 0.0;
        for e in &self.epochs {
            if !e.seconds.is_finite() {
                return None;
            }
            total += if e.seconds >= last { e.seconds - last } else { e.seconds };
            last = e.seconds;
        }
        (!self.epochs.is_empty()).then(|| total / self.epochs.len() as f64)
    }

    /// The epoch with the lowest test loss.
    pub fn best(&self) -> Option<(usize, f64)> {
        self.epochs.iter().filter_map(|e| Some((e.epoch, e.test_loss?))).min_by(|a, b| a.1.total_cmp(&b.1))
    }

    /// The last epoch with a test loss: (epoch, train loss, test loss).
    pub fn last_tested(&self) -> Option<(usize, f64, f64)> {
        self.epochs.iter().rev().find_map(|e| Some((e.epoch, e.train_loss, e.test_loss?)))
    }
}

/// The mean of the finite values, if any.
pub fn mean(values: impl IntoIterator<Item = f64>) -> Option<f64> {
    let v: Vec<f64> = values.into_iter().filter(|x| x.is_finite()).collect();
    (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
}
