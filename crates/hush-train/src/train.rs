//! The training loop.

use std::ops::ControlFlow;
use std::sync::mpsc::sync_channel;
use std::time::{Duration, Instant};

use candle_core::{DType, Device, Module, Tensor};
use candle_nn::{VarBuilder, VarMap};
use hush_net::{ALIGNMENT, LossSpace, Net, Pretrained, hwc_to_nchw, init_weights, save_weights};
use serde::{Deserialize, Serialize};

use crate::checkpoint::{TrainState, load_checkpoint, save_checkpoint};
use crate::sample::{Crop, Sampler, gather};
use crate::{Optimizer, Result, TrainConfig, TrainError, TrainSample};

/// One line of the loss log.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct LossRow {
    /// 1-based optimizer step.
    pub step: usize,
    /// 1-based epoch the step belongs to (an epoch is [`TrainConfig::steps_per_epoch`] steps).
    pub epoch: usize,
    /// The training loss of the step's batch, before the update.
    pub loss: f64,
    /// The learning rate of the update.
    pub lr: f64,
    /// Wall-clock seconds since training (or this resumed part of it) started.
    pub seconds: f64,
}

/// One line of the per-epoch metrics.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct EpochRow {
    pub epoch: usize,
    /// The epoch's last step.
    pub step: usize,
    /// Mean training loss of the epoch's steps.
    pub train_loss: f64,
    /// Mean loss on the test samples (whole images), every `eval_every` epochs and at the end.
    pub test_loss: Option<f64>,
    /// The learning rate of the epoch.
    pub lr: f64,
    pub seconds: f64,
    /// The share of the epoch's wall time the step waited for its batch (0: the loader never stalls it).
    pub loader_share: f64,
    /// This epoch's test loss is the lowest so far.
    pub best: bool,
}

/// What the observer hears after every step.
#[derive(Clone, Debug)]
pub struct StepReport {
    pub row: LossRow,
    /// At the end of an epoch: its metrics, and a checkpoint (see [`read_train_state`](crate::read_train_state))
    /// to continue from. Writing it to disk is the caller's job.
    pub epoch: Option<(EpochRow, Vec<u8>)>,
}

/// A finished (or stopped) run.
pub struct Trained {
    /// Self-describing weights after the last completed step.
    pub weights: Vec<u8>,
    /// The network's variables, for using the result in-process.
    pub varmap: VarMap,
    /// One row per completed step (of this call).
    pub log: Vec<LossRow>,
    /// One row per completed epoch (of this call).
    pub epochs: Vec<EpochRow>,
    /// True if the observer asked to stop before `steps`.
    pub stopped_early: bool,
    /// The test loss of the initial weights of a run that starts from trained ones ([`Start::Init`]), before
    /// any step: what fine-tuning must beat.
    pub initial_test_loss: Option<f64>,
    /// Seconds the steps waited for batches, and seconds of training in total.
    pub loader_seconds: f64,
    pub seconds: f64,
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

/// Where a run's weights come from.
#[derive(Clone, Copy, Debug)]
pub enum Start<'a> {
    /// Random weights from the configuration's seed ([`init_weights`]).
    Fresh,
    /// Trained weights (fine-tuning), adapted to the configuration's features ([`Pretrained::adapt`]);
    /// the configuration's `init` records which.
    Init(&'a Pretrained),
    /// A checkpoint of an earlier run of the same configuration (see [`read_train_state`](crate::read_train_state)).
    Resume(&'a [u8]),
}

/// A batch prepared by the loader thread.
struct Batch {
    crops: Vec<Crop>,
    input: Vec<f32>,
    target: Vec<f32>,
}

/// Trains a network (a U-Net or the patch MLP) on `train` samples, measuring the loss on `test` samples (may be
/// empty) every `eval_every` epochs.
///
/// Every step draws `batch` random `crop`² windows (see [`TrainConfig`]), computes the loss and updates the
/// weights with the configured optimizer at the schedule's learning rate for the step's epoch. Batches
/// are prepared on a background thread one step ahead. After each step `observer` gets a [`StepReport`]
/// (with a checkpoint at the end of each epoch); returning `ControlFlow::Break(())` stops training after
/// that step. `start` says where the weights come from; from a checkpoint ([`Start::Resume`]) training
/// continues after its step exactly as the uninterrupted run would have. A run whose configuration records
/// initial weights (`cfg.init`) must start from them or resume.
///
/// Samples are checked first: a NaN or infinite value is a [`TrainError::Data`] naming the sample and
/// pixel. A non-finite loss or gradient during training is a [`TrainError::Diverged`] naming the step and
/// the batch, carrying the weights from before that step.
pub fn train(
    cfg: &TrainConfig,
    train: &[TrainSample],
    test: &[TrainSample],
    device: &Device,
    start: Start<'_>,
    mut observer: impl FnMut(StepReport) -> ControlFlow<()>,
) -> Result<Trained> {
    cfg.validate()?;
    check_samples(cfg, train, "training")?;
    check_samples(cfg, test, "test")?;
    let info = cfg.model_info();
    let epoch_steps = cfg.steps_per_epoch(train.len());
    let epochs = cfg.steps.div_ceil(epoch_steps);

    let varmap = VarMap::new();
    let net = Net::new(VarBuilder::from_varmap(&varmap, DType::F32, device), &cfg.net)?;
    let mut opt = Optimizer::for_layers(cfg.optimizer.clone(), &varmap, &cfg.trainable)?;
    let mut best = None;
    let first_step = match start {
        Start::Fresh if cfg.init.is_some() => {
            return Err(TrainError::Config(format!(
                "the configuration starts from {}, but no initial weights were given",
                cfg.init.as_ref().map_or("", |i| i.source.as_str())
            )));
        }
        Start::Fresh => {
            init_weights(&varmap, cfg.seed)?;
            1
        }
        Start::Init(weights) => {
            if cfg.init.is_none() {
                return Err(TrainError::Config(
                    "initial weights were given, but the configuration does not record them (set `init`)".into(),
                ));
            }
            let adapted = weights
                .adapt(&cfg.features)
                .and_then(|w| w.with_head(cfg.net.head()))
                .map_err(|e| TrainError::Config(e.to_string()))?;
            // Where a kernel head averages has no weights: the configuration decides it.
            if adapted.info.net.with_kernel_linear(cfg.net.kernel_linear()) != cfg.net
                || adapted.info.transfer != cfg.transfer
            {
                return Err(TrainError::Config(format!(
                    "the initial weights are a {} with the {:?} transfer, the configuration asks for a {} with {:?}",
                    adapted.info.net.describe(),
                    adapted.info.transfer,
                    cfg.net.describe(),
                    cfg.transfer
                )));
            }
            adapted.load_into(&varmap).map_err(|e| TrainError::Config(e.to_string()))?;
            1
        }
        Start::Resume(bytes) => {
            let state = load_checkpoint(bytes, cfg, &varmap, &mut opt, device)?;
            let changed: Vec<String> = state
                .config
                .differences(cfg)
                .into_iter()
                .filter(|(k, _, _)| !matches!(k.as_str(), "steps" | "eval_every"))
                .map(|(k, a, b)| format!("{k}: {a} in the checkpoint, {b} now"))
                .collect();
            if !changed.is_empty() {
                return Err(TrainError::Config(format!(
                    "cannot resume: the run would not continue as it started ({})",
                    changed.join("; ")
                )));
            }
            if state.step % epoch_steps != 0 && state.step != state.config.steps {
                return Err(TrainError::Config(format!(
                    "cannot resume: the checkpoint is at step {}, not at the end of an epoch of {epoch_steps} steps",
                    state.step
                )));
            }
            best = state.best;
            state.step + 1
        }
    };
    let initial_test_loss = match start {
        Start::Init(_) if !test.is_empty() => Some(test_loss(&net, cfg, test, device)?),
        _ => None,
    };

    let vars: Vec<_> = opt.vars().iter().map(|(_, v)| v.clone()).collect();
    let start = Instant::now();
    let mut log = Vec::new();
    let mut epoch_rows = Vec::new();
    let mut stopped_early = false;
    let mut loader_wait = Duration::ZERO;
    let (mut epoch_losses, mut epoch_start, mut epoch_wait) = (Vec::new(), Instant::now(), Duration::ZERO);
    let sampler = Sampler::new(cfg.seed, train, cfg.crop, cfg.augment);

    std::thread::scope(|scope| -> Result<()> {
        let (tx, rx) = sync_channel::<Batch>(1);
        let mut loader = sampler.clone();
        let last_step = cfg.steps;
        scope.spawn(move || {
            for step in first_step..=last_step {
                let crops = loader.batch(step, cfg.batch);
                let input = gather(train, &cfg.features, &crops, false, cfg.crop);
                let target = gather(train, &cfg.features, &crops, true, cfg.crop);
                if tx.send(Batch { crops, input, target }).is_err() {
                    break;
                }
            }
        });
        for step in first_step..=cfg.steps {
            let waited = Instant::now();
            let batch = rx.recv().map_err(|_| TrainError::Data("the batch loader thread stopped".into()))?;
            loader_wait += waited.elapsed();
            epoch_wait += waited.elapsed();
            let epoch = (step - 1) / epoch_steps + 1;
            let lr = cfg.schedule.lr(cfg.lr, epoch, epochs);
            let (n, c, s) = (cfg.batch, cfg.net.in_channels(), cfg.crop);
            let input = Tensor::from_vec(batch.input, (n, c, s, s), device)?;
            let target = Tensor::from_vec(batch.target, (n, 3, s, s), device)?;
            let output = net.forward(&input)?;
            let loss = objective(cfg, &output, &target)?;
            let value = loss.to_dtype(DType::F64)?.to_scalar::<f64>()?;
            let diverged = |cause: String, log: Vec<LossRow>| -> Result<()> {
                let weights = save_weights(&varmap, &info)?;
                let last_good = Trained {
                    weights,
                    varmap: varmap.clone(),
                    log,
                    epochs: vec![],
                    stopped_early: true,
                    initial_test_loss,
                    loader_seconds: 0.0,
                    seconds: 0.0,
                };
                let batch = batch.crops.iter().map(|c| c.to_string()).collect::<Vec<_>>().join(", ");
                Err(TrainError::Diverged { step, batch, cause, last_good: Box::new(last_good) })
            };
            if !value.is_finite() {
                return diverged(
                    format!(
                        "the loss is {value}; the inputs were checked finite, so the learning rate ({lr}) is likely \
                         too high or the input values far outside [0, 1]"
                    ),
                    std::mem::take(&mut log),
                );
            }
            let grads = loss.backward()?;
            let mut norm2 = 0f64;
            for var in &vars {
                if let Some(g) = grads.get(var) {
                    norm2 += g.sqr()?.sum_all()?.to_dtype(DType::F64)?.to_scalar::<f64>()?;
                }
            }
            let norm = norm2.sqrt();
            if !norm.is_finite() {
                return diverged(
                    format!(
                        "the loss ({value}) is finite but the gradient is not (norm {norm}); the learning rate \
                         ({lr}) is likely too high{}",
                        if cfg.clip_grad_norm.is_none() { ", or try gradient clipping" } else { "" }
                    ),
                    std::mem::take(&mut log),
                );
            }
            let scale = match cfg.clip_grad_norm {
                Some(max) if norm > max => max / (norm + 1e-6),
                _ => 1.0,
            };
            opt.step(&grads, lr, scale)?;
            let row = LossRow { step, epoch, loss: value, lr, seconds: start.elapsed().as_secs_f64() };
            log.push(row);
            epoch_losses.push(value);

            let mut report = StepReport { row, epoch: None };
            if step % epoch_steps == 0 || step == cfg.steps {
                let evaluate = step == cfg.steps || (cfg.eval_every > 0 && epoch.is_multiple_of(cfg.eval_every));
                let test_loss =
                    if evaluate && !test.is_empty() { Some(test_loss(&net, cfg, test, device)?) } else { None };
                let is_best = test_loss.is_some_and(|t| best.is_none_or(|(_, b)| t < b));
                if is_best {
                    best = test_loss.map(|t| (epoch, t));
                }
                let seconds = epoch_start.elapsed().as_secs_f64();
                let epoch_row = EpochRow {
                    epoch,
                    step,
                    train_loss: epoch_losses.iter().sum::<f64>() / epoch_losses.len() as f64,
                    test_loss,
                    lr,
                    seconds: row.seconds,
                    loader_share: epoch_wait.as_secs_f64() / seconds.max(1e-12),
                    best: is_best,
                };
                let state = TrainState {
                    step,
                    epoch,
                    crops_drawn: (step * cfg.batch) as u64,
                    optimizer_steps: opt.step_count(),
                    best,
                    config: cfg.clone(),
                };
                epoch_rows.push(epoch_row);
                report.epoch = Some((epoch_row, save_checkpoint(&varmap, &opt, &state)?));
                (epoch_losses, epoch_start, epoch_wait) = (Vec::new(), Instant::now(), Duration::ZERO);
            }
            if observer(report).is_break() {
                stopped_early = step < cfg.steps;
                break;
            }
        }
        Ok(())
    })?;
    let weights = save_weights(&varmap, &info)?;
    Ok(Trained {
        weights,
        varmap,
        log,
        epochs: epoch_rows,
        stopped_early,
        initial_test_loss,
        loader_seconds: loader_wait.as_secs_f64(),
        seconds: start.elapsed().as_secs_f64(),
    })
}

/// The mean loss over whole test images (each cropped centrally to a multiple of 16 per side).
fn test_loss(net: &Net, cfg: &TrainConfig, test: &[TrainSample], device: &Device) -> Result<f64> {
    let net = net.frozen()?;
    let mut sum = 0.0;
    for s in test {
        let (w, h) = (s.input.width, s.input.height);
        let (w16, h16) = (w / ALIGNMENT * ALIGNMENT, h / ALIGNMENT * ALIGNMENT);
        let (x0, y0) = ((w - w16) / 2, (h - h16) / 2);
        let crop = |im: &hush_dataset::Image| -> Result<Tensor> {
            let t = hwc_to_nchw(&im.data, w, h, im.channels, device)?;
            Ok(t.narrow(2, y0, h16)?.narrow(3, x0, w16)?)
        };
        let output = net.forward(&crop(&s.input)?)?;
        sum += objective(cfg, &output, &crop(&s.target)?)?.to_dtype(DType::F64)?.to_scalar::<f64>()?;
    }
    Ok(sum / test.len() as f64)
}

/// What a run minimizes: its loss in its loss space, plus the weighted colour-mean term on the display images.
fn objective(cfg: &TrainConfig, output: &Tensor, target: &Tensor) -> Result<Tensor> {
    let loss = cfg.loss_space.compute(cfg.loss, cfg.transfer, output, target)?;
    if cfg.color_mean == 0.0 {
        return Ok(loss);
    }
    let display = |t: &Tensor| LossSpace::Tonemapped.map(cfg.transfer, t);
    let term = hush_net::loss::color_mean(&display(output)?, &display(target)?)?;
    Ok((loss + (term * cfg.color_mean)?)?)
}

/// Channel counts, sizes and finiteness of every sample, before any work.
fn check_samples(cfg: &TrainConfig, samples: &[TrainSample], what_set: &str) -> Result<()> {
    if samples.is_empty() && what_set == "training" {
        return Err(TrainError::Data("no training samples".into()));
    }
    let want = cfg.net.in_channels();
    let min = if what_set == "training" { cfg.crop } else { ALIGNMENT };
    for (i, s) in samples.iter().enumerate() {
        let (inp, tgt) = (&s.input, &s.target);
        if inp.channels != want || tgt.channels != 3 {
            return Err(TrainError::Data(format!(
                "{what_set} sample {i}: input has {} channels and target {}, the network needs {want} (features {}) \
                 and 3",
                inp.channels, tgt.channels, cfg.features
            )));
        }
        if (inp.width, inp.height) != (tgt.width, tgt.height) {
            return Err(TrainError::Data(format!(
                "{what_set} sample {i}: input is {}x{} but target is {}x{}",
                inp.width, inp.height, tgt.width, tgt.height
            )));
        }
        if inp.width < min || inp.height < min {
            return Err(TrainError::Data(format!(
                "{what_set} sample {i} is {}x{}, smaller than the {min}x{min} crop",
                inp.width, inp.height
            )));
        }
        for (what, im) in [("input", inp), ("target", tgt)] {
            if im.data.len() != im.width * im.height * im.channels {
                return Err(TrainError::Data(format!(
                    "{what_set} sample {i} {what}: data length does not match its size"
                )));
            }
            if let Some(k) = im.data.iter().position(|v| !v.is_finite()) {
                let (p, c) = (k / im.channels, k % im.channels);
                return Err(TrainError::Data(format!(
                    "{what_set} sample {i} {what} is non-finite ({}) at x={} y={} channel {c}; clean the data (e.g. \
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
