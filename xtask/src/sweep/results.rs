//! What a run left behind, read defensively: `train/metrics.csv` (loss per epoch), `train/summary.json`
//! and `eval/summary.json` (schema 1: seconds; schema 2: render_seconds, denoise_seconds, ms_ssim, flip).

use std::path::Path;

use serde_json::Value;

use super::spec::Run;
use crate::util::read_json;

/// One row of `metrics.csv`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Epoch {
    pub epoch: usize,
    pub train_loss: f64,
    pub test_loss: Option<f64>,
    /// Seconds since the training (or its resumed part) started.
    pub seconds: f64,
}

/// One row of `eval/summary.json`.
#[derive(Clone, Debug, PartialEq)]
pub struct EvalRow {
    pub view: String,
    pub method: String,
    pub spp: u64,
    pub psnr: Option<f64>,
    pub ssim: Option<f64>,
    pub mae: Option<f64>,
    pub rel_mse: Option<f64>,
    /// Render seconds of a noisy image or a reference.
    pub render_seconds: Option<f64>,
    /// Denoise seconds of a model.
    pub denoise_seconds: Option<f64>,
    /// The PNG preview, relative to the evaluation folder.
    pub preview: Option<String>,
}

/// One image of `eval/summary.json`'s figures (crops of the worst window, difference pictures).
#[derive(Clone, Debug, PartialEq)]
pub struct Picture {
    /// The figure's title: `<view> at <spp> spp: crops` or `<view> at <spp> spp: pixels off by ...`.
    pub title: String,
    /// The method (crops) or `<method>: <share> % > 3 %, <share> % > 10 %` (difference pictures).
    pub caption: String,
    /// Relative to the evaluation folder.
    pub path: String,
}

/// A run and its results (empty where a file is missing).
#[derive(Clone, Debug)]
pub struct RunResult {
    pub run: Run,
    pub done: bool,
    pub epochs: Vec<Epoch>,
    pub eval: Vec<EvalRow>,
    pub pictures: Vec<Picture>,
}

pub fn parse_metrics_csv(text: &str) -> Vec<Epoch> {
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap_or_default().split(',').collect();
    let col = |name: &str| header.iter().position(|h| h.trim() == name);
    let (Some(e), Some(tr)) = (col("epoch"), col("train_loss")) else { return Vec::new() };
    let (te, s) = (col("test_loss"), col("seconds"));
    lines
        .filter_map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            let num = |i: Option<usize>| i.and_then(|i| f.get(i)?.trim().parse::<f64>().ok());
            Some(Epoch {
                epoch: f.get(e)?.trim().parse().ok()?,
                train_loss: num(Some(tr))?,
                test_loss: num(te),
                seconds: num(s).unwrap_or(f64::NAN),
            })
        })
        .collect()
}

pub fn parse_eval(summary: &Value) -> Vec<EvalRow> {
    let rows = summary["rows"].as_array().cloned().unwrap_or_default();
    rows.iter()
        .filter_map(|r| {
            let method = r["method"].as_str()?.to_string();
            let f = |k: &str| r[k].as_f64();
            let is_image = matches!(method.as_str(), "noisy" | "reference");
            Some(EvalRow {
                view: r["view"].as_str()?.to_string(),
                spp: r["spp"].as_u64()?,
                psnr: f("psnr"),
                ssim: f("ssim"),
                mae: f("mae"),
                rel_mse: f("rel_mse"),
                render_seconds: f("render_seconds").or(if is_image { f("seconds") } else { None }),
                denoise_seconds: f("denoise_seconds").or(if is_image { None } else { f("seconds") }),
                preview: r["preview"].as_str().map(String::from),
                method,
            })
        })
        .collect()
}

/// The images of the figures of an evaluation summary.
pub fn parse_pictures(summary: &Value) -> Vec<Picture> {
    let figures = summary["figures"].as_array().cloned().unwrap_or_default();
    figures
        .iter()
        .flat_map(|f| {
            let title = f["title"].as_str().unwrap_or_default().to_string();
            let images = f["images"].as_array().cloned().unwrap_or_default();
            images.into_iter().filter_map(move |i| {
                Some(Picture {
                    title: title.clone(),
                    caption: i["caption"].as_str()?.to_string(),
                    path: i["path"].as_str()?.to_string(),
                })
            })
        })
        .collect()
}

impl RunResult {
    pub fn load(run: &Run, dir: &Path) -> RunResult {
        let epochs = parse_metrics_csv(&std::fs::read_to_string(dir.join("train/metrics.csv")).unwrap_or_default());
        let summary = read_json(&dir.join("eval/summary.json"));
        let eval = summary.as_ref().map(parse_eval).unwrap_or_default();
        let pictures = summary.as_ref().map(parse_pictures).unwrap_or_default();
        RunResult { run: run.clone(), done: dir.join("done.json").is_file(), epochs, eval, pictures }
    }

    /// `method`'s crop of the worst window of `view` at `spp` (`hush eval`'s figure `<view> at <spp> spp:
    /// crops`), relative to the evaluation folder.
    pub fn crop(&self, view: &str, spp: u64, method: &str) -> Option<&str> {
        let title = format!("{view} at {spp} spp: crops");
        self.pictures.iter().find(|p| p.title == title && p.caption == method).map(|p| p.path.as_str())
    }

    /// `method`'s difference picture of `view` at `spp` and the shares of pixels it marks (the caption after
    /// the method's name).
    pub fn difference(&self, view: &str, spp: u64, method: &str) -> Option<(&str, &str)> {
        let title = format!("{view} at {spp} spp: pixels off");
        let prefix = format!("{method}: ");
        self.pictures.iter().find_map(|p| {
            let shares = p.caption.strip_prefix(&prefix)?;
            p.title.starts_with(&title).then_some((p.path.as_str(), shares))
        })
    }

    /// The rows of the trained model (the method that is neither `noisy` nor `reference`, preferring
    /// `train/model`).
    pub fn model_rows(&self) -> Vec<&EvalRow> {
        let is_model = |m: &str| m == "train/model";
        let any_model = |m: &str| !matches!(m, "noisy" | "reference");
        let pick: &dyn Fn(&str) -> bool =
            if self.eval.iter().any(|r| is_model(&r.method)) { &is_model } else { &any_model };
        self.eval.iter().filter(|r| pick(&r.method)).collect()
    }

    pub fn noisy_rows(&self) -> Vec<&EvalRow> {
        self.eval.iter().filter(|r| r.method == "noisy").collect()
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn metrics_csv_with_gaps_and_a_resume() {
        let csv = "epoch,step,train_loss,test_loss,lr,seconds,loader_share,best\n\
                   1,2,0.5,0.6,0.001,10,0.1,true\n2,4,0.4,,0.001,20,0.1,false\n\
                   3,6,0.3,0.7,0.001,5,0.1,false\nbroken\n";
        let r = RunResult {
            run: crate::sweep::spec::parse_sweep("x", "", Path::new("x.toml")).unwrap().runs(&tiny())[0].clone(),
            done: true,
            epochs: parse_metrics_csv(csv),
            eval: Vec::new(),
            pictures: Vec::new(),
        };
        assert_eq!(r.epochs.len(), 3);
        assert_eq!(r.epochs[1].test_loss, None);
        // 10 + 10 + 5 (the clock restarted at the resume) over 3 epochs.
        assert!((r.seconds_per_epoch().unwrap() - 25.0 / 3.0).abs() < 1e-12);
        assert_eq!(r.best(), Some((1, 0.6)));
        assert_eq!(r.last_tested(), Some((3, 0.3, 0.7)));
    }

    fn tiny() -> crate::sweep::spec::Scale {
        let t = "[tiny]\nscenes=[\"a\"]\n[small]\nscenes=[\"a\"]\n[thesis]\nscenes=[\"a\"]\n";
        crate::sweep::spec::parse_scales(t, Path::new("s.toml")).unwrap().remove(0)
    }

    #[test]
    fn eval_rows_of_both_schemas() {
        let v1 = serde_json::json!({"rows": [
            {"view": "v", "method": "noisy", "spp": 4, "psnr": 20.0, "ssim": 0.5, "seconds": 1.5, "preview": "p/n.png"},
            {"view": "v", "method": "train/model", "spp": 4, "psnr": 30.0, "seconds": 0.2},
        ]});
        let rows = parse_eval(&v1);
        assert_eq!(rows[0].render_seconds, Some(1.5));
        assert_eq!(rows[0].denoise_seconds, None);
        assert_eq!(rows[0].preview.as_deref(), Some("p/n.png"));
        assert_eq!(rows[1].denoise_seconds, Some(0.2));
        assert_eq!(rows[1].ssim, None);
        let v2 = serde_json::json!({"schema": 2, "rows": [
            {"view": "v", "method": "train/model", "spp": 4, "psnr": 30.0, "render_seconds": 1.5,
             "denoise_seconds": 0.3, "ms_ssim": 0.9},
            {"view": "v", "method": "oidn", "spp": 4, "psnr": 33.0, "denoise_seconds": 0.1},
        ]});
        let rows = parse_eval(&v2);
        assert_eq!((rows[0].render_seconds, rows[0].denoise_seconds), (Some(1.5), Some(0.3)));
        let r =
            RunResult { run: RunResult::load_dummy(), done: true, epochs: Vec::new(), eval: rows, pictures: vec![] };
        assert_eq!(r.model_rows().len(), 1);
        assert_eq!(r.model_rows()[0].method, "train/model");
    }

    /// The crops and difference pictures of `hush eval`'s figures, found by view, spp and method.
    #[test]
    fn pictures_of_the_figures() {
        let summary = serde_json::json!({"schema": 2, "rows": [], "figures": [
            {"title": "v at 4 spp: crops", "images": [
                {"caption": "noisy", "path": "pictures/v_000004_noisy_crop.png"},
                {"caption": "train/model", "path": "pictures/v_000004_train-model_crop.png"},
                {"caption": "reference", "path": "pictures/v_000004_reference_crop.png"}]},
            {"title": "v at 4 spp: pixels off by more than 3 % and 10 %", "images": [
                {"caption": "noisy: 40.0 % > 3 %, 9.0 % > 10 %", "path": "pictures/v_000004_noisy_diff.png"},
                {"caption": "train/model: 12.5 % > 3 %, 1.0 % > 10 %", "path": "pictures/v_model_diff.png"}]},
            {"title": "v at 16 spp: crops", "images": [{"caption": "train/model", "path": "pictures/16.png"}]},
        ]});
        let r = RunResult {
            run: RunResult::load_dummy(),
            done: true,
            epochs: Vec::new(),
            eval: Vec::new(),
            pictures: parse_pictures(&summary),
        };
        assert_eq!(r.pictures.len(), 6);
        assert_eq!(r.crop("v", 4, "train/model"), Some("pictures/v_000004_train-model_crop.png"));
        assert_eq!(r.crop("v", 16, "train/model"), Some("pictures/16.png"));
        assert_eq!(r.crop("v", 4, "reference"), Some("pictures/v_000004_reference_crop.png"));
        assert_eq!(r.crop("w", 4, "train/model"), None);
        assert_eq!(
            r.difference("v", 4, "train/model"),
            Some(("pictures/v_model_diff.png", "12.5 % > 3 %, 1.0 % > 10 %"))
        );
        assert_eq!(r.difference("v", 16, "train/model"), None);
    }

    impl RunResult {
        fn load_dummy() -> Run {
            crate::sweep::spec::parse_sweep("x", "", Path::new("x.toml")).unwrap().runs(&tiny())[0].clone()
        }
    }
}
