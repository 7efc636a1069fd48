//! [`TrainConfig`]: everything that determines a training run.

use hush_net::transfer::Transfer;
use hush_net::{ALIGNMENT, Features, Loss, ModelInfo, UNetConfig};
use serde::{Deserialize, Serialize};

use crate::{Result, TrainError};

/// A training run: network, data layout, loss and optimizer settings. Serializable so a run directory
/// can keep it (as OIDN's `config.json`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TrainConfig {
    /// Auxiliary input features; the samples' input channels must be `features.in_channels()`.
    pub features: Features,
    /// The transfer function the samples' color and target went through (recorded in the weights).
    pub transfer: Transfer,
    pub net: UNetConfig,
    pub loss: Loss,
    /// Adam's learning rate, constant (the thesis: 1e-4).
    pub lr: f64,
    /// Optimizer steps (batches) in total.
    pub steps: usize,
    /// Crops per batch.
    pub batch: usize,
    /// Side of the square random crops; a multiple of 16 (the thesis and OIDN: 256).
    pub crop: usize,
    /// Seeds the initial weights and the crop sequence: same seed, same data, same run.
    pub seed: u64,
    /// Hand out weights every this many steps (0: never).
    pub checkpoint_every: usize,
    /// Random flips and transposition of the crops (8 orientations, as OIDN).
    pub augment: bool,
}

impl TrainConfig {
    /// The thesis' recipe for `features` at full OIDN width: MIX loss, Adam at a constant 1e-4, 256² crops,
    /// PU transfer. `steps`, `batch` and `checkpoint_every` are placeholders to adjust to the machine.
    pub fn thesis(features: Features) -> Self {
        let net = UNetConfig::oidn(features.in_channels());
        TrainConfig {
            features,
            transfer: Transfer::Pu,
            net,
            loss: Loss::Mix,
            lr: 1e-4,
            steps: 1000,
            batch: 4,
            crop: 256,
            seed: 0,
            checkpoint_every: 100,
            augment: true,
        }
    }

    /// What the weights file records about this run.
    pub fn model_info(&self) -> ModelInfo {
        ModelInfo { net: self.net.clone(), features: self.features.clone(), transfer: self.transfer }
    }

    /// Checks the fields against each other.
    pub fn validate(&self) -> Result<()> {
        let bad = |m: String| Err(TrainError::Config(m));
        self.model_info().validate().map_err(|e| TrainError::Config(e.to_string()))?;
        if self.net.out_channels != 3 {
            return bad(format!("the network must have 3 output channels (RGB), not {}", self.net.out_channels));
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
        Ok(())
    }
}
