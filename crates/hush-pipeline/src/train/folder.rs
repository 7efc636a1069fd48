//! A run folder: what `hush train` writes and reads back, and the rules for continuing a run in it.
//!
//! ```text
//! RUN/config.json                    the RunConfig
//! RUN/loss.csv, RUN/metrics.csv      a row per step, a row per epoch (hush_train::LOSS_COLUMNS, METRICS_COLUMNS)
//! RUN/checkpoints/last.safetensors   the resume point: weights, optimizer and training state
//! RUN/checkpoints/epoch_NNNN.safetensors, RUN/best.safetensors, RUN/model.safetensors (the final weights)
//! RUN/last_good.safetensors          the weights from before a step that diverged
//! RUN/summary.json, RUN/loss.svg
//! ```

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use hush_dataset::write_atomic;
use hush_train::{EpochRow, LossRow, loss_csv, metrics_csv, parse_loss_csv, parse_metrics_csv, plot_losses};

use super::RunConfig;

/// The files of a run folder.
///
/// ```
/// let run = hush_pipeline::RunFolder::new("runs/a");
/// assert_eq!(run.last_checkpoint(), std::path::Path::new("runs/a/checkpoints/last.safetensors"));
/// assert_eq!(run.epoch_checkpoint(7), std::path::Path::new("runs/a/checkpoints/epoch_0007.safetensors"));
/// assert_eq!(run.read_config().unwrap(), None, "no config.json: not a run yet");
/// ```
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RunFolder {
    pub dir: PathBuf,
}

impl RunFolder {
    pub const LOSS_PLOT: &'static str = "loss.svg";

    pub fn new(dir: impl Into<PathBuf>) -> Self {
        RunFolder { dir: dir.into() }
    }

    pub fn config(&self) -> PathBuf {
        self.dir.join("config.json")
    }

    pub fn loss_csv(&self) -> PathBuf {
        self.dir.join("loss.csv")
    }

    pub fn metrics_csv(&self) -> PathBuf {
        self.dir.join("metrics.csv")
    }

    pub fn checkpoints(&self) -> PathBuf {
        self.dir.join("checkpoints")
    }

    /// The resume point.
    pub fn last_checkpoint(&self) -> PathBuf {
        self.checkpoints().join("last.safetensors")
    }

    pub fn epoch_checkpoint(&self, epoch: usize) -> PathBuf {
        self.checkpoints().join(format!("epoch_{epoch:04}.safetensors"))
    }

    /// The weights of the epoch with the lowest test loss.
    pub fn best(&self) -> PathBuf {
        self.dir.join("best.safetensors")
    }

    /// The final weights.
    pub fn model(&self) -> PathBuf {
        self.dir.join("model.safetensors")
    }

    /// The weights from before a step that diverged.
    pub fn last_good(&self) -> PathBuf {
        self.dir.join("last_good.safetensors")
    }

    pub fn summary(&self) -> PathBuf {
        self.dir.join("summary.json")
    }

    pub fn loss_plot(&self) -> PathBuf {
        self.dir.join(Self::LOSS_PLOT)
    }

    /// The run's `config.json`, if the folder has one.
    pub fn read_config(&self) -> Result<Option<RunConfig>> {
        let path = self.config();
        if !path.is_file() {
            return Ok(None);
        }
        let text = std::fs::read_to_string(&path).with_context(|| format!("reading {}", path.display()))?;
        let config = serde_json::from_str(&text)
            .with_context(|| format!("{} is not a hush run configuration", path.display()))?;
        Ok(Some(config))
    }

    /// The logs as far as step `step` and epoch `epoch` (a resumed run drops what came after its checkpoint).
    pub fn read_logs(&self, step: usize, epoch: usize) -> (Vec<LossRow>, Vec<EpochRow>) {
        let mut log = parse_loss_csv(&std::fs::read_to_string(self.loss_csv()).unwrap_or_default());
        log.retain(|r| r.step <= step);
        let mut metrics = parse_metrics_csv(&std::fs::read_to_string(self.metrics_csv()).unwrap_or_default());
        metrics.retain(|r| r.epoch <= epoch);
        (log, metrics)
    }

    /// Writes `loss.csv`.
    pub fn write_loss_csv(&self, log: &[LossRow]) -> Result<()> {
        write_file(&self.loss_csv(), loss_csv(log).as_bytes())
    }
}

pub(crate) fn write_file(path: &Path, bytes: &[u8]) -> Result<()> {
    write_atomic(path, |tmp| std::fs::write(tmp, bytes)).with_context(|| format!("writing {}", path.display()))
}

/// Explains how `now` differs from the run `stored` in a way that keeps it from continuing; empty if it
/// may continue (only the budget, evaluation frequency and device may change).
pub fn incompatibilities(stored: &RunConfig, now: &RunConfig) -> Vec<String> {
    let mut out: Vec<String> = stored
        .train
        .differences(&now.train)
        .into_iter()
        .filter(|(k, _, _)| !matches!(k.as_str(), "steps" | "eval_every"))
        // The starting weights are the same when their bytes and features are, wherever the file now lies (a
        // clone at another path, a relative path given from another folder).
        .filter(|(k, _, _)| {
            k != "init"
                || !matches!((&stored.train.init, &now.train.init),
                    (Some(a), Some(b)) if a.fnv1a == b.fnv1a && a.features == b.features)
        })
        .map(|(k, a, b)| match k.as_str() {
            "features" => format!("features: {} in the run, {} now", stored.train.features, now.train.features),
            "init" => {
                let show = |i: &Option<hush_train::InitRecord>| match i {
                    Some(i) => format!("{} (FNV-1a {})", i.source, i.fnv1a),
                    None => "random weights".into(),
                };
                format!("init: {} in the run, {} now", show(&stored.train.init), show(&now.train.init))
            }
            _ => format!("{k}: {a} in the run, {b} now"),
        })
        .collect();
    if stored.dataset != now.dataset {
        out.push(format!("dataset: {} in the run, {} now", stored.dataset.display(), now.dataset.display()));
    }
    if stored.aux != now.aux {
        out.push(format!("aux: {} in the run, {} now", stored.aux, now.aux));
    }
    if stored.validation != now.validation {
        out.push(format!("validation: {:?} in the run, {:?} now", stored.validation, now.validation));
    }
    if stored.exclude != now.exclude {
        out.push(format!("exclude: {:?} in the run, {:?} now", stored.exclude, now.exclude));
    }
    if stored.spp != now.spp {
        out.push(format!("spp: {:?} in the run, {:?} now", stored.spp, now.spp));
    }
    out
}

/// The end of an epoch on disk: the logs first, then the checkpoints, the plot, and last the resume point
/// `checkpoints/last.safetensors` (each file written atomically), so a killed run resumes from a
/// consistent epoch and drops the log rows after it.
pub(crate) fn save_epoch(
    folder: &RunFolder,
    log: &[LossRow],
    metrics: &[EpochRow],
    row: &EpochRow,
    bytes: &[u8],
) -> Result<()> {
    write_file(&folder.loss_csv(), loss_csv(log).as_bytes())?;
    write_file(&folder.metrics_csv(), metrics_csv(metrics).as_bytes())?;
    if row.test_loss.is_some() {
        write_file(&folder.epoch_checkpoint(row.epoch), bytes)?;
        write_file(&folder.loss_plot(), plot_losses(metrics, 800, 500).as_bytes())?;
    }
    if row.best {
        write_file(&folder.best(), bytes)?;
    }
    write_file(&folder.last_checkpoint(), bytes)
}

/// `sample 3 at (...)` → `cbox_v001@4spp at (...)`.
pub(crate) fn name_batch(batch: &str, names: &[String]) -> String {
    batch
        .split(", ")
        .map(|item| {
            let index = item.strip_prefix("sample ").and_then(|r| r.split(' ').next()?.parse::<usize>().ok());
            match index.and_then(|i| names.get(i).map(|n| (i, n))) {
                Some((i, n)) => item.replacen(&format!("sample {i}"), n, 1),
                None => item.to_string(),
            }
        })
        .collect::<Vec<_>>()
        .join(", ")
}

#[cfg(test)]
mod tests {
    use super::*;
    use hush_net::{Feature, InputFeatures};
    use hush_train::{InitRecord, TrainConfig};

    fn config(init: Option<InitRecord>) -> RunConfig {
        let features = InputFeatures { aux: vec![Feature::Albedo, Feature::Normal] };
        let mut train = TrainConfig::thesis(features);
        train.init = init;
        RunConfig {
            dataset: "d".into(),
            spp: vec![],
            device: "cpu".into(),
            aux: hush_dataset::AuxSource::Noisy,
            validation: vec![],
            exclude: vec![],
            train,
        }
    }

    /// The starting weights are named by their bytes: the same file at another path continues the run, other
    /// bytes (or none) do not.
    #[test]
    fn init_weights_are_compared_by_their_bytes() {
        let features = InputFeatures { aux: vec![Feature::Albedo, Feature::Normal] };
        let at = |path: &str, bytes: &[u8]| Some(InitRecord::of(path, bytes, features.clone()));
        let stored = config(at("data/weights/w.tza", b"abc"));
        assert!(incompatibilities(&stored, &config(at("/elsewhere/data/weights/w.tza", b"abc"))).is_empty());
        let other = incompatibilities(&stored, &config(at("data/weights/w.tza", b"abd")));
        assert_eq!(other.len(), 1, "{other:?}");
        assert!(other[0].starts_with("init: data/weights/w.tza (FNV-1a"), "{other:?}");
        let none = incompatibilities(&stored, &config(None));
        assert!(none.len() == 1 && none[0].ends_with("random weights now"), "{none:?}");
    }
}
