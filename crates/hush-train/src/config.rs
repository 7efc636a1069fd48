//! [`TrainConfig`]: everything that determines a training run.

use hush_net::transfer::Transfer;
use hush_net::{ALIGNMENT, InputFeatures, Loss, LossSpace, ModelInfo, NetConfig, UNetConfig};
use serde::{Deserialize, Serialize};

use crate::{Augment, OptimizerConfig, Result, Schedule, TrainError};

/// A training run: network, data layout, loss, optimizer and schedule. Serializable so a run directory
/// can keep it (as OIDN's `config.json`) and a checkpoint can tell whether it belongs to it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TrainConfig {
    /// Auxiliary input features; the samples' input channels must be `features.in_channels()`.
    pub features: InputFeatures,
    /// The transfer function the samples' color and target went through (recorded in the weights).
    pub transfer: Transfer,
    /// A U-Net or the patch MLP; run configurations from before the patch MLP read as U-Nets.
    pub net: NetConfig,
    pub loss: Loss,
    /// Where the loss compares output and target; absent from configurations written before it existed.
    #[serde(default, skip_serializing_if = "LossSpace::is_transfer")]
    pub loss_space: LossSpace,
    /// The weight of [`hush_net::loss::color_mean`] added to the loss, measured on the evaluation's display
    /// images whatever the loss space (0: none; absent from configurations written before it existed).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub color_mean: f64,
    pub optimizer: OptimizerConfig,
    /// The base learning rate the schedule scales (the thesis: 1e-4, constant; for one-cycle the maximum).
    pub lr: f64,
    pub schedule: Schedule,
    /// Optimizer steps (batches) in total.
    pub steps: usize,
    /// Steps per epoch; 0 means one pass over the training samples, `⌈samples / batch⌉`.
    pub epoch_steps: usize,
    /// Crops per batch.
    pub batch: usize,
    /// Side of the square random crops; a multiple of 16 (the thesis and OIDN: 256).
    pub crop: usize,
    pub augment: Augment,
    /// Seeds the initial weights and the crop sequence: same seed, same data, same run.
    pub seed: u64,
    /// Every this many epochs (and after the last step): the test loss, and a checkpoint to keep. 0: at the
    /// end only.
    pub eval_every: usize,
    /// Scale the gradients down so that their global L2 norm is at most this.
    pub clip_grad_norm: Option<f64>,
    /// The trained weights the run starts from (fine-tuning); `None`: from [`hush_net::init_weights`]'s
    /// random weights of `seed`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub init: Option<InitRecord>,
    /// The layers the optimizer updates (by name, e.g. `dec_conv0`); the others keep their weights. Empty:
    /// every layer. Fine-tuning a few layers adapts trained weights to a renderer with little room to learn
    /// the training scenes themselves.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub trainable: Vec<String>,
}

fn is_zero(x: &f64) -> bool {
    *x == 0.0
}

/// Which trained weights a run started from, as `config.json` records it: enough to tell whether a resumed
/// or repeated run starts from the same ones.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct InitRecord {
    /// The file, as the user named it.
    pub source: String,
    /// FNV-1a (64-bit) of the file's bytes, in hex.
    pub fnv1a: String,
    /// The input features the weights were trained with, before [`hush_net::Pretrained::adapt`].
    pub features: InputFeatures,
}

impl InitRecord {
    /// The record of weights read from `source` (its `bytes`) that take `features`.
    pub fn of(source: impl Into<String>, bytes: &[u8], features: InputFeatures) -> Self {
        InitRecord { source: source.into(), fnv1a: format!("{:016x}", hush_hash::fnv1a(bytes)), features }
    }
}

impl TrainConfig {
    /// The thesis' recipe for `features` at full OIDN width: MIX loss, Adam at a constant 1e-4, 256² crops,
    /// PU transfer, flips. `steps`, `batch` and `eval_every` are placeholders to adjust to the machine.
    pub fn thesis(features: InputFeatures) -> Self {
        let net = UNetConfig::oidn(features.in_channels()).into();
        TrainConfig {
            features,
            transfer: Transfer::Pu,
            net,
            loss: Loss::Mix,
            loss_space: LossSpace::Transfer,
            color_mean: 0.0,
            optimizer: OptimizerConfig::adam(),
            lr: 1e-4,
            schedule: Schedule::Constant,
            steps: 1000,
            epoch_steps: 0,
            batch: 4,
            crop: 256,
            augment: Augment::Flips,
            seed: 0,
            eval_every: 10,
            clip_grad_norm: None,
            init: None,
            trainable: Vec::new(),
        }
    }

    /// What the weights file records about this run.
    pub fn model_info(&self) -> ModelInfo {
        ModelInfo { net: self.net.clone(), features: self.features.clone(), transfer: self.transfer }
    }

    /// Steps per epoch with `samples` training samples.
    pub fn steps_per_epoch(&self, samples: usize) -> usize {
        if self.epoch_steps > 0 { self.epoch_steps } else { samples.div_ceil(self.batch.max(1)).max(1) }
    }

    /// Checks the fields against each other.
    pub fn validate(&self) -> Result<()> {
        let bad = |m: String| Err(TrainError::Config(m));
        self.model_info().validate().map_err(|e| TrainError::Config(e.to_string()))?;
        if self.net.out_channels() != 3 {
            return bad(format!("the network must have 3 output channels (RGB), not {}", self.net.out_channels()));
        }
        if !(self.lr.is_finite() && self.lr > 0.0) {
            return bad(format!("learning rate must be finite and > 0, got {}", self.lr));
        }
        if self.steps == 0 || self.batch == 0 {
            return bad(format!("steps ({}) and batch ({}) must be > 0", self.steps, self.batch));
        }
        if self.crop == 0 || !self.crop.is_multiple_of(ALIGNMENT) {
            return bad(format!("crop must be a non-zero multiple of {ALIGNMENT}, got {}", self.crop));
        }
        if !(self.color_mean.is_finite() && self.color_mean >= 0.0) {
            return bad(format!("the colour-mean weight must be finite and ≥ 0, got {}", self.color_mean));
        }
        if let Some(c) = self.clip_grad_norm
            && !(c.is_finite() && c > 0.0)
        {
            return bad(format!("gradient clipping norm must be finite and > 0, got {c}"));
        }
        self.optimizer.validate().map_err(TrainError::Config)?;
        self.schedule.validate().map_err(TrainError::Config)?;
        Ok(())
    }

    /// The fields whose values differ between `self` and `other`, as `(name, self's value, other's value)`
    /// in JSON.
    pub fn differences(&self, other: &TrainConfig) -> Vec<(String, String, String)> {
        let (a, b) = (serde_json::to_value(self), serde_json::to_value(other));
        let (Ok(serde_json::Value::Object(a)), Ok(serde_json::Value::Object(b))) = (a, b) else {
            return vec![];
        };
        // A field left out of one side (an empty default) differs from a value on the other.
        let show = |v: Option<&serde_json::Value>| v.map(|v| v.to_string()).unwrap_or_else(|| "(none)".into());
        let keys: Vec<&String> = a.keys().chain(b.keys().filter(|k| !a.contains_key(*k))).collect();
        keys.into_iter()
            .filter(|k| a.get(*k) != b.get(*k))
            .map(|k| (k.clone(), show(a.get(k)), show(b.get(k))))
            .collect()
    }
}
