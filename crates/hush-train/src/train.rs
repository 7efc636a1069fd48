//! The training loop.

use std::ops::ControlFlow;
use std::time::Instant;

use candle_core::{DType, Device, Module};
use candle_nn::{AdamW, Optimizer, ParamsAdamW, VarBuilder, VarMap};
use hush_net::{UNet, init_weights, load_weights, read_metadata, save_weights};
use serde::{Deserialize, Serialize};

use crate::sample::{Sampler, gather};
use crate::{Result, TrainConfig, TrainError, TrainSample};

/// One line of the loss log.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct LossRow {
    /// 1-based optimizer step.
    pub step: usize,
    /// 1-based pass over the samples (each epoch visits every sample once, in a new random order) that
    /// the step's last crop belongs to.
    pub epoch: usize,
    /// The training loss of the step's batch, before the update.
    pub loss: f64,
    /// Wall-clock seconds since training started.
    pub seconds: f64,
}

/// What the observer hears after every step.
#[derive(Clone, Debug)]
pub struct StepReport {
    pub row: LossRow,
    /// Self-describing weights (see [`hush_net::save_weights`]) after this step's update, at every
    /// `checkpoint_every`-th step. Writing them to disk is the caller's job (e.g. with
    /// `hush_dataset::write_atomic`).
    pub checkpoint: Option<Vec<u8>>,
}

/// Where to continue from: weights written by an earlier run of the same configuration and the number of
/// steps that run had done. The crop sequence continues exactly; Adam's moments start again from zero
/// (candle does not expose them).
#[derive(Clone, Copy, Debug)]
pub struct Resume<'a> {
    pub weights: &'a [u8],
    pub step: usize,
}

/// A finished (or stopped) run.
pub struct Trained {
    /// Self-describing weights after the last completed step.
    pub weights: Vec<u8>,
    /// The network's variables, for using the result in-process.
    pub varmap: VarMap,
    /// One row per completed step.
    pub log: Vec<LossRow>,
    /// True if the observer asked to stop before `steps`.
    pub stopped_early: bool,
}

impl std::fmt::Debug for Trained {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Trained")
            .field("weights", &format_args!("{} bytes", self.weights.len()))
            .field("log", &format_args!("{} rows, last {:?}", self.log.len(), self.log.last()))
            .field("stopped_early", &self.stopped_early)
            .finish()
    }
}

/// Trains a U-Net on `samples` with Adam (AdamW with weight decay 0) at a constant learning rate.
///
/// Every step draws `batch` random `crop`² windows (see [`TrainConfig`]), computes the loss, and updates
/// the weights. After each step `observer` gets a [`StepReport`]; returning `ControlFlow::Break(())`
/// stops training after that step (the result has `stopped_early`). Samples are checked first: a NaN or
/// infinite value is a [`TrainError::Data`] naming the sample and pixel. A non-finite loss or gradient
/// during training is a [`TrainError::Diverged`] carrying the weights from before that step.
pub fn train(
    cfg: &TrainConfig,
    samples: &[TrainSample],
    device: &Device,
    resume: Option<Resume>,
    mut observer: impl FnMut(StepReport) -> ControlFlow<()>,
) -> Result<Trained> {
    cfg.validate()?;
    check_samples(cfg, samples)?;
    let info = cfg.model_info();

    let varmap = VarMap::new();
    let net = UNet::new(VarBuilder::from_varmap(&varmap, DType::F32, device), &cfg.net)?;
    let mut sampler = Sampler::new(cfg.seed, samples, cfg.crop, cfg.augment);
    let first_step = match resume {
        None => {
            init_weights(&varmap, cfg.seed)?;
            1
        }
        Some(r) => {
            match read_metadata(r.weights)? {
                Some(stored) if stored == info => {}
                Some(stored) => {
                    return Err(TrainError::Config(format!(
                        "cannot resume: the weights were trained with {} (features {}) but this run is {} \
                         (features {})",
                        serde_json::to_string(&stored.net).unwrap_or_default(),
                        stored.features,
                        serde_json::to_string(&info.net).unwrap_or_default(),
                        info.features
                    )));
                }
                None => {
                    return Err(TrainError::Config("cannot resume: the weights carry no hush metadata".into()));
                }
            }
            load_weights(&varmap, r.weights)?;
            for _ in 0..r.step * cfg.batch {
                sampler.next_crop();
            }
            r.step + 1
        }
    };

    let params = ParamsAdamW { lr: cfg.lr, weight_decay: 0.0, ..ParamsAdamW::default() };
    let vars = varmap.all_vars();
    let mut opt = AdamW::new(vars.clone(), params)?;
    let start = Instant::now();
    let mut log = Vec::new();
    let mut stopped_early = false;
    for step in first_step..=cfg.steps {
        let crops: Vec<_> = (0..cfg.batch).map(|_| sampler.next_crop()).collect();
        let epoch = sampler.epoch;
        let input = gather(samples, &crops, |s| &s.input, cfg.crop, device)?;
        let target = gather(samples, &crops, |s| &s.target, cfg.crop, device)?;
        let output = net.forward(&input)?;
        let loss = cfg.loss.compute(&output, &target)?;
        let value = loss.to_dtype(DType::F64)?.to_scalar::<f64>()?;
        let diverged = |cause: String, log: Vec<LossRow>| -> Result<Trained> {
            let weights = save_weights(&varmap, &info)?;
            let last_good = Trained { weights, varmap: varmap.clone(), log, stopped_early: true };
            Err(TrainError::Diverged { step, cause, last_good: Box::new(last_good) })
        };
        if !value.is_finite() {
            return diverged(
                format!(
                    "the loss is {value}; the inputs were checked finite, so the learning rate ({}) is likely \
                     too high or the input values far outside [0, 1]",
                    cfg.lr
                ),
                log,
            );
        }
        let grads = loss.backward()?;
        for var in &vars {
            if let Some(g) = grads.get(var) {
                let sum = g.abs()?.sum_all()?.to_dtype(DType::F64)?.to_scalar::<f64>()?;
                if !sum.is_finite() {
                    return diverged(
                        format!(
                            "the loss ({value}) is finite but a gradient is not (sum |g| = {sum}); the learning \
                             rate ({}) is likely too high",
                            cfg.lr
                        ),
                        log,
                    );
                }
            }
        }
        opt.step(&grads)?;
        let row = LossRow { step, epoch, loss: value, seconds: start.elapsed().as_secs_f64() };
        log.push(row);
        let checkpoint = if cfg.checkpoint_every > 0 && step % cfg.checkpoint_every == 0 {
            Some(save_weights(&varmap, &info)?)
        } else {
            None
        };
        if observer(StepReport { row, checkpoint }).is_break() {
            stopped_early = step < cfg.steps;
            break;
        }
    }
    let weights = save_weights(&varmap, &info)?;
    Ok(Trained { weights, varmap, log, stopped_early })
}

/// Channel counts, sizes and finiteness of every sample, before any work.
fn check_samples(cfg: &TrainConfig, samples: &[TrainSample]) -> Result<()> {
    if samples.is_empty() {
        return Err(TrainError::Data("no training samples".into()));
    }
    let want = cfg.net.in_channels;
    for (i, s) in samples.iter().enumerate() {
        let (inp, tgt) = (&s.input, &s.target);
        if inp.channels != want || tgt.channels != 3 {
            return Err(TrainError::Data(format!(
                "sample {i}: input has {} channels and target {}, the network needs {want} (features {}) and 3",
                inp.channels, tgt.channels, cfg.features
            )));
        }
        if (inp.width, inp.height) != (tgt.width, tgt.height) {
            return Err(TrainError::Data(format!(
                "sample {i}: input is {}x{} but target is {}x{}",
                inp.width, inp.height, tgt.width, tgt.height
            )));
        }
        if inp.width < cfg.crop || inp.height < cfg.crop {
            return Err(TrainError::Data(format!(
                "sample {i} is {}x{}, smaller than the {}x{} crop",
                inp.width, inp.height, cfg.crop, cfg.crop
            )));
        }
        for (what, im) in [("input", inp), ("target", tgt)] {
            if im.data.len() != im.width * im.height * im.channels {
                return Err(TrainError::Data(format!("sample {i} {what}: data length does not match its size")));
            }
            if let Some(k) = im.data.iter().position(|v| !v.is_finite()) {
                let (p, c) = (k / im.channels, k % im.channels);
                return Err(TrainError::Data(format!(
                    "sample {i} {what} is non-finite ({}) at x={} y={} channel {c}; clean the data (e.g. \
                     hush_dataset::check_finite) before training",
                    im.data[k],
                    p % im.width,
                    p / im.width
                )));
            }
        }
    }
    Ok(())
}
