//! `hush train`: options from flags and/or a TOML file, one typed [`RunConfig`] saved as `config.json`,
//! and the run folder: loss and metric logs, checkpoints, the best and the final model, a loss plot.

use std::ops::ControlFlow;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use clap::Args;
use hush_dataset::{Image, Manifest, Split, load_view, write_atomic};
use hush_hash::fnv1a;
use hush_net::transfer::Transfer;
use hush_net::{Activation, InputFeatures, Loss, NetConfig, PatchMlpConfig, UNetConfig, UNetKind};
use hush_train::{
    Augment, EpochRow, LossRow, OptimizerConfig, PREPARATION_VERSION, Schedule, TrainConfig, TrainError, TrainSample,
    decode_samples, plot_losses, read_train_state, round_trip, train,
};
use indicatif::{ProgressBar, ProgressStyle};
use serde::{Deserialize, Serialize};

use crate::denoiser::aux_of;

/// Every option can also be set in a `--config` TOML file under the flag's name (`eval-every = 5`);
/// flags override the file.
#[derive(Args, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields, rename_all = "kebab-case")]
pub struct TrainArgs {
    /// TOML file with any of the options below, named as the flags (`lr = 1e-4`, `features = "dsnn"`).
    #[arg(long)]
    #[serde(skip)]
    pub config: Option<PathBuf>,
    /// Continue the run in this folder exactly where it stopped (from its last checkpoint and
    /// config.json). Only --steps, --epochs, --eval-every and --device may change.
    #[arg(long)]
    #[serde(skip)]
    pub resume: Option<PathBuf>,
    /// Dataset folder (from `hush dataset`): its training split is trained on, its test split measured.
    #[arg(long)]
    pub dataset: Option<PathBuf>,
    /// Run folder: config.json, loss.csv, metrics.csv, checkpoints/, best.safetensors, model.safetensors.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Input features: `color`, `color,albedo,normal` or `color,diffuse,specular,normal`, or the thesis's
    /// names M_n, M_ann, M_dsnn [default: color,albedo,normal].
    #[arg(long)]
    pub features: Option<String>,
    /// Noisy images of these spp are the inputs (all of them if not given).
    #[arg(long, value_delimiter = ',')]
    pub spp: Option<Vec<u32>>,
    /// Network: unet (OIDN's), unet_small, unet_large, autoencoder (the thesis's M_DAE), or patch_mlp (Burger et
    /// al.'s MLP on 17×17 patches at stride 3, tanh; patch_mlp_relu with ReLU) [default: unet].
    #[arg(long)]
    pub arch: Option<String>,
    /// Width multiplier of the network (1.0 = OIDN's widths; the thesis's M1 0.66, M2 0.33; for patch_mlp, of
    /// four hidden layers of 2047 units) [default: 0.25].
    #[arg(long)]
    pub width: Option<f64>,
    /// Loss: l1, mse, ssim, msssim, mix (0.16·L1 + 0.84·(1 − MS-SSIM)), mape, smape, l1_grad [default: mix].
    #[arg(long)]
    pub loss: Option<String>,
    /// Optimizer: adam, adamw (decoupled weight decay 0.01), sgd, sgd_momentum (0.9) [default: adam].
    #[arg(long)]
    pub optimizer: Option<String>,
    /// Base learning rate (for one_cycle its maximum) [default: 1e-3].
    #[arg(long)]
    pub lr: Option<f64>,
    /// Learning-rate schedule per epoch: constant, step[:every:gamma], lambda:f1,f2,..., exponential[:gamma],
    /// cosine[:min_lr], sgdr[:t0:t_mult], one_cycle [default: constant].
    #[arg(long)]
    pub schedule: Option<String>,
    /// Train this many epochs (instead of --steps).
    #[arg(long, conflicts_with = "steps")]
    pub epochs: Option<usize>,
    /// Optimizer steps in total [default: 300].
    #[arg(long)]
    pub steps: Option<usize>,
    /// Steps per epoch [default: one pass over the training images, ⌈images / batch⌉].
    #[arg(long)]
    pub epoch_steps: Option<usize>,
    /// Batch size [default: 4].
    #[arg(long)]
    pub batch: Option<usize>,
    /// Square crop size, a multiple of 16 (the thesis: 256) [default: 64].
    #[arg(long)]
    pub crop: Option<usize>,
    /// Augmentation: crop (random crops only), flips (and 8 orientations), full (and OIDN's channel
    /// permutations) [default: flips].
    #[arg(long)]
    pub augment: Option<String>,
    /// Seed of the initial weights and of the crops [default: 0].
    #[arg(long)]
    pub seed: Option<u64>,
    /// Every N epochs: test loss, checkpoints/epoch_N.safetensors, the loss plot [default: 10].
    #[arg(long, alias = "checkpoint-every")]
    pub eval_every: Option<usize>,
    /// Clip the gradients' global L2 norm to this.
    #[arg(long)]
    pub clip_grad_norm: Option<f64>,
    /// cpu, or cuda when built with `--features cuda` [default: cpu].
    #[arg(long)]
    pub device: Option<String>,
}

/// Everything a run is: where its data comes from, where it runs, and the training configuration.
/// Saved as `config.json` in the run folder.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RunConfig {
    pub dataset: PathBuf,
    /// The spp of the noisy inputs (empty: all).
    pub spp: Vec<u32>,
    /// `cpu` or `cuda`.
    pub device: String,
    pub train: TrainConfig,
}

const LOSS_PLOT: &str = "loss-train_blue-test_red.png";

impl TrainArgs {
    /// Fills every option not given here from `file`.
    fn or(self, file: TrainArgs) -> TrainArgs {
        macro_rules! merge {
            ($($f:ident),*) => { TrainArgs { config: self.config, resume: self.resume, $($f: self.$f.or(file.$f)),* } };
        }
        merge!(
            dataset,
            out,
            features,
            spp,
            arch,
            width,
            loss,
            optimizer,
            lr,
            schedule,
            epochs,
            steps,
            epoch_steps,
            batch,
            crop,
            augment,
            seed,
            eval_every,
            clip_grad_norm,
            device
        )
    }
}

/// The thesis's feature-set names as aliases of feature lists.
fn parse_features(s: &str) -> Result<InputFeatures> {
    let alias = match s.trim().to_ascii_lowercase().trim_start_matches("m_") {
        "n" => Some("color"),
        "ann" => Some("albedo,normal"),
        "dsnn" => Some("diffuse,specular,normal"),
        _ => None,
    };
    Ok(InputFeatures::parse(alias.unwrap_or(s))?)
}

/// A `--arch`: a U-Net kind or the patch MLP with its activation.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Arch {
    UNet(UNetKind),
    PatchMlp(Activation),
}

impl Arch {
    /// The network of this arch for `in_channels` input channels at width multiplier `width`.
    fn config(self, in_channels: usize, width: f64) -> NetConfig {
        match self {
            Arch::UNet(kind) => UNetConfig { kind, in_channels, out_channels: 3, width }.into(),
            Arch::PatchMlp(activation) => PatchMlpConfig::burger(in_channels, width, activation).into(),
        }
    }
}

fn parse_arch(s: &str) -> Result<Arch> {
    match s {
        "oidn" => Ok(Arch::UNet(UNetKind::Unet)),
        "dae" | "m_dae" => Ok(Arch::UNet(UNetKind::Autoencoder)),
        "patch_mlp" | "mlp" => Ok(Arch::PatchMlp(Activation::Tanh)),
        "patch_mlp_relu" => Ok(Arch::PatchMlp(Activation::Relu)),
        _ => UNetKind::parse(s).map(Arch::UNet).with_context(|| {
            format!("unknown --arch '{s}': use unet, unet_small, unet_large, autoencoder, patch_mlp or patch_mlp_relu")
        }),
    }
}

fn parse_loss(s: &str) -> Result<Loss> {
    Ok(match s {
        "l1" | "mae" => Loss::L1,
        "l2" | "mse" => Loss::Mse,
        "ssim" => Loss::Ssim,
        "msssim" | "ms-ssim" | "ms_ssim" => Loss::MsSsim,
        "mix" | "l1_msssim" => Loss::Mix,
        _ => serde_json::from_value(serde_json::Value::String(s.into()))
            .map_err(|_| anyhow::anyhow!("unknown loss '{s}': use l1, mse, ssim, msssim or mix"))?,
    })
}

/// Builds the run's configuration from the options, taking what they do not give from `base` (the run
/// being resumed) or else the defaults; `train_images` sizes an epoch.
fn resolve(args: &TrainArgs, base: Option<&RunConfig>, train_images: usize) -> Result<RunConfig> {
    let b = base.map(|c| &c.train);
    let features = match &args.features {
        Some(f) => parse_features(f)?,
        None => b.map_or_else(|| parse_features("color,albedo,normal"), |b| Ok(b.features.clone()))?,
    };
    let base_arch = b.map(|b| match &b.net {
        NetConfig::PatchMlp(c) => Arch::PatchMlp(c.activation),
        NetConfig::UNet(c) => Arch::UNet(c.kind),
    });
    let arch = match &args.arch {
        Some(a) => parse_arch(a)?,
        None => base_arch.unwrap_or(Arch::UNet(UNetKind::Unet)),
    };
    let net = match (b, args.width) {
        // Resuming with the run's own kind of network and no new width: the run's network as it was (an
        // MLP's hidden sizes, σ and patch included), whatever repeats its `--arch`.
        (Some(b), None) if base_arch == Some(arch) => b.net.with_in_channels(features.in_channels()),
        (b, width) => {
            let base_width = b.and_then(|b| b.net.as_unet()).map(|c| c.width);
            arch.config(features.in_channels(), width.or(base_width).unwrap_or(0.25))
        }
    };
    let optimizer = match &args.optimizer {
        Some(o) => OptimizerConfig::parse(o)
            .with_context(|| format!("unknown --optimizer '{o}': use adam, adamw, sgd or sgd_momentum"))?,
        None => b.map_or_else(OptimizerConfig::adam, |b| b.optimizer.clone()),
    };
    let augment = match &args.augment {
        Some(a) => Augment::parse(a).with_context(|| format!("unknown --augment '{a}': use crop, flips or full"))?,
        None => b.map_or(Augment::Flips, |b| b.augment),
    };
    let loss = match &args.loss {
        Some(l) => parse_loss(l)?,
        None => b.map_or(Loss::Mix, |b| b.loss),
    };
    let batch = args.batch.or(b.map(|b| b.batch)).unwrap_or(4);
    let epoch_steps =
        args.epoch_steps.or(b.map(|b| b.epoch_steps)).unwrap_or(train_images.div_ceil(batch.max(1)).max(1));
    let steps = match args.epochs {
        Some(e) => e * epoch_steps,
        None => args.steps.or(b.map(|b| b.steps)).unwrap_or(300),
    };
    let epochs = steps.div_ceil(epoch_steps.max(1));
    let schedule = match &args.schedule {
        Some(s) => Schedule::parse(s, epochs).with_context(|| {
            format!(
                "unknown --schedule '{s}': use constant, step[:every:gamma], lambda:f1,f2,..., \
                 exponential[:gamma], cosine[:min_lr], sgdr[:t0:t_mult] or one_cycle"
            )
        })?,
        None => b.map_or(Schedule::Constant, |b| b.schedule.clone()),
    };
    let device = args.device.clone().or(base.map(|c| c.device.clone())).unwrap_or_else(|| "cpu".into());
    if !matches!(device.as_str(), "cpu" | "cuda") {
        bail!("unknown --device '{device}': use cpu or cuda");
    }
    let train = TrainConfig {
        features,
        transfer: Transfer::Pu,
        net,
        loss,
        optimizer,
        lr: args.lr.or(b.map(|b| b.lr)).unwrap_or(1e-3),
        schedule,
        steps,
        epoch_steps,
        batch,
        crop: args.crop.or(b.map(|b| b.crop)).unwrap_or(64),
        augment,
        seed: args.seed.or(b.map(|b| b.seed)).unwrap_or(0),
        eval_every: args.eval_every.or(b.map(|b| b.eval_every)).unwrap_or(10),
        clip_grad_norm: args.clip_grad_norm.or(b.and_then(|b| b.clip_grad_norm)),
    };
    train.validate()?;
    let dataset = args
        .dataset
        .clone()
        .or(base.map(|c| c.dataset.clone()))
        .context("--dataset is required (or `dataset = ...` in --config)")?;
    let spp = args.spp.clone().or(base.map(|c| c.spp.clone())).unwrap_or_default();
    Ok(RunConfig { dataset, spp, device, train })
}

fn device(name: &str) -> Result<candle_core::Device> {
    match name {
        "cuda" => {
            #[cfg(feature = "cuda")]
            return Ok(candle_core::Device::new_cuda(0)?);
            #[cfg(not(feature = "cuda"))]
            bail!("--device cuda: this hush was built without CUDA; rebuild with `cargo build -p hush --features cuda`")
        }
        _ => Ok(candle_core::Device::Cpu),
    }
}

/// The samples of one split at the configured spp, named `scene_view@spp`: from the split's f16 cache
/// beside the dataset (`DATASET/cache/`) when it is intact and was made from this manifest, feature set,
/// transfer and spp; otherwise prepared from the EXR files and cached for the next run.
fn load_split(cfg: &RunConfig, manifest: &Manifest, split: Split) -> Result<(Vec<TrainSample>, Vec<String>)> {
    let features = &cfg.train.features;
    let records: Vec<_> = manifest
        .split(split)
        .flat_map(|view| {
            view.noisy.iter().filter(|r| cfg.spp.is_empty() || cfg.spp.contains(&r.spp)).map(move |r| (view, r.spp))
        })
        .collect();
    let names: Vec<String> =
        records.iter().map(|(view, spp)| format!("{}_{}@{spp}spp", view.scene, view.view)).collect();
    // The file is named by what the samples are (features, transfer, split, views and spp), so a changed
    // dataset replaces its cache rather than adding one; the key inside also covers the records of this
    // split's views (files, seeds, sizes) and how samples are prepared, and a mismatch rebuilds the file.
    let what =
        format!("features {features}, transfer {:?}, {split:?} split, samples {}", Transfer::Pu, names.join(" "));
    let views: Vec<_> = manifest.split(split).collect();
    let key = format!("views {:016x}, preparation {PREPARATION_VERSION}, {what}", fnv1a(&serde_json::to_vec(&views)?));
    let path = cfg.dataset.join("cache").join(format!("{split:?}-{:016x}.f16", fnv1a(what.as_bytes())).to_lowercase());
    let samples = cached_samples(&path, &key, || {
        let mut samples = Vec::new();
        for &(view, spp) in &records {
            let images = load_view(&cfg.dataset, view, spp)?;
            let aux: Vec<&Image> = features.aux.iter().map(|&f| aux_of(&images, f)).collect();
            samples.push(TrainSample::from_linear(features, Transfer::Pu, &images.color, &aux, &images.reference)?);
        }
        Ok(samples)
    })?;
    if split == Split::Train {
        for (s, name) in samples.iter().zip(&names) {
            if s.input.width.min(s.input.height) < cfg.train.crop {
                bail!(
                    "{name} is {}×{}, smaller than --crop {}: use a smaller crop or a larger dataset --size",
                    s.input.width,
                    s.input.height,
                    cfg.train.crop
                );
            }
        }
    }
    Ok((samples, names))
}

/// Prepared samples from the cache file `path` if it holds intact samples of `key`; otherwise from `build`,
/// written to `path` (atomically) for the next run. Either way the samples are what the cache gives back
/// (values rounded to f16), so a run trains on the same data whether its cache was built or read. A cache
/// that cannot be written (a read-only dataset) is a warning.
fn cached_samples(
    path: &Path,
    key: &str,
    build: impl FnOnce() -> Result<Vec<TrainSample>>,
) -> Result<Vec<TrainSample>> {
    match std::fs::read(path) {
        Ok(bytes) => match decode_samples(&bytes, key) {
            Ok(samples) => return Ok(samples),
            Err(e) => eprintln!("warning: {}: {e}; preparing the samples again", path.display()),
        },
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
        Err(e) => eprintln!("warning: cannot read {}: {e}; preparing the samples again", path.display()),
    }
    let samples = build()?;
    let (samples, bytes) = round_trip(key, &samples)?;
    let written = match path.parent() {
        Some(dir) => std::fs::create_dir_all(dir)
            .with_context(|| format!("creating {}", dir.display()))
            .and_then(|()| write_file(path, &bytes)),
        None => Ok(()),
    };
    if let Err(e) = written {
        eprintln!("warning: the sample cache is not saved ({e:#}); the next run prepares the samples again");
    }
    Ok(samples)
}

fn write_file(path: &Path, bytes: &[u8]) -> Result<()> {
    write_atomic(path, |tmp| std::fs::write(tmp, bytes)).with_context(|| format!("writing {}", path.display()))
}

fn loss_csv(log: &[LossRow]) -> String {
    let mut csv = String::from("step,epoch,loss,lr,seconds\n");
    for r in log {
        csv.push_str(&format!("{},{},{},{},{:.3}\n", r.step, r.epoch, r.loss, r.lr, r.seconds));
    }
    csv
}

fn metrics_csv(rows: &[EpochRow]) -> String {
    let mut csv = String::from("epoch,step,train_loss,test_loss,lr,seconds,loader_share,best\n");
    for r in rows {
        let test = r.test_loss.map(|t| t.to_string()).unwrap_or_default();
        csv.push_str(&format!(
            "{},{},{},{test},{},{:.3},{:.4},{}\n",
            r.epoch, r.step, r.train_loss, r.lr, r.seconds, r.loader_share, r.best
        ));
    }
    csv
}

fn parse_loss_csv(csv: &str) -> Vec<LossRow> {
    csv.lines()
        .skip(1)
        .filter_map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            Some(LossRow {
                step: f.first()?.parse().ok()?,
                epoch: f.get(1)?.parse().ok()?,
                loss: f.get(2)?.parse().ok()?,
                lr: f.get(3)?.parse().ok()?,
                seconds: f.get(4)?.parse().ok()?,
            })
        })
        .collect()
}

fn parse_metrics_csv(csv: &str) -> Vec<EpochRow> {
    csv.lines()
        .skip(1)
        .filter_map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            Some(EpochRow {
                epoch: f.first()?.parse().ok()?,
                step: f.get(1)?.parse().ok()?,
                train_loss: f.get(2)?.parse().ok()?,
                test_loss: f.get(3)?.parse().ok(),
                lr: f.get(4)?.parse().ok()?,
                seconds: f.get(5)?.parse().ok()?,
                loader_share: f.get(6)?.parse().ok()?,
                best: f.get(7)?.parse().ok()?,
            })
        })
        .collect()
}

/// Explains how `now` differs from the run `stored` in a way that keeps it from continuing; empty if it
/// may continue (only the budget, evaluation frequency and device may change).
fn incompatibilities(stored: &RunConfig, now: &RunConfig) -> Vec<String> {
    let mut out: Vec<String> = stored
        .train
        .differences(&now.train)
        .into_iter()
        .filter(|(k, _, _)| !matches!(k.as_str(), "steps" | "eval_every"))
        .map(|(k, a, b)| match k.as_str() {
            "features" => format!("features: {} in the run, {} now", stored.train.features, now.train.features),
            _ => format!("{k}: {a} in the run, {b} now"),
        })
        .collect();
    if stored.dataset != now.dataset {
        out.push(format!("dataset: {} in the run, {} now", stored.dataset.display(), now.dataset.display()));
    }
    if stored.spp != now.spp {
        out.push(format!("spp: {:?} in the run, {:?} now", stored.spp, now.spp));
    }
    out
}

pub fn run(args: TrainArgs) -> Result<()> {
    let args = match &args.config {
        Some(path) => {
            let text = std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
            let file: TrainArgs = toml::from_str(&text).with_context(|| format!("parsing {}", path.display()))?;
            args.or(file)
        }
        None => args,
    };
    // With --resume the run folder's config.json supplies every option not given.
    let stored: Option<RunConfig> = {
        let out = args.resume.as_ref().or(args.out.as_ref()).context("--out is required (or --resume RUN)")?;
        let path = out.join("config.json");
        if path.is_file() {
            let text = std::fs::read_to_string(&path).with_context(|| format!("reading {}", path.display()))?;
            Some(
                serde_json::from_str(&text)
                    .with_context(|| format!("{} is not a hush run configuration", path.display()))?,
            )
        } else if let Some(run) = &args.resume {
            bail!("--resume {}: no config.json there; is it a run folder of `hush train`?", run.display());
        } else {
            None
        }
    };
    let out = args.resume.clone().or(args.out.clone()).expect("checked above");
    if let (Some(r), Some(o)) = (&args.resume, &args.out)
        && r != o
    {
        bail!("--resume {} and --out {} name different folders; give one", r.display(), o.display());
    }
    let base = if args.resume.is_some() { stored.as_ref() } else { None };
    let dataset = args
        .dataset
        .clone()
        .or(base.map(|c| c.dataset.clone()))
        .context("--dataset is required (or `dataset = ...` in --config)")?;
    let manifest = Manifest::load(&dataset)?;
    let spp = args.spp.clone().or(base.map(|c| c.spp.clone())).unwrap_or_default();
    let train_images = manifest
        .split(Split::Train)
        .map(|v| v.noisy.iter().filter(|r| spp.is_empty() || spp.contains(&r.spp)).count())
        .sum::<usize>();
    if train_images == 0 {
        bail!("{} has no training images at spp {spp:?}", dataset.display());
    }
    let cfg = resolve(&args, base, train_images)?;

    let checkpoints = out.join("checkpoints");
    let last = checkpoints.join("last.safetensors");
    let config_path = out.join("config.json");
    let resume_bytes = match &stored {
        Some(stored) if last.is_file() => {
            let problems = incompatibilities(stored, &cfg);
            if !problems.is_empty() {
                bail!(
                    "{} holds a run that this command cannot continue ({}); choose another --out, or delete the \
                     folder to start over",
                    out.display(),
                    problems.join("; ")
                );
            }
            Some(std::fs::read(&last).with_context(|| format!("reading {}", last.display()))?)
        }
        _ if args.resume.is_some() => bail!("--resume {}: it has no checkpoints/last.safetensors yet", out.display()),
        _ => None,
    };
    // The samples after the cheap checks above, before anything is written.
    let loading = std::time::Instant::now();
    let (samples, names) = load_split(&cfg, &manifest, Split::Train)?;
    let (test, _) = load_split(&cfg, &manifest, Split::Test)?;
    let load_seconds = loading.elapsed().as_secs_f64();
    std::fs::create_dir_all(&checkpoints).with_context(|| format!("creating {}", checkpoints.display()))?;
    write_file(&config_path, serde_json::to_string_pretty(&cfg)?.as_bytes())?;

    let (mut log, mut metrics) = (Vec::new(), Vec::new());
    let mut start_step = 0;
    if let Some(bytes) = &resume_bytes {
        let state = read_train_state(bytes)?.context("checkpoints/last.safetensors carries no training state")?;
        log = parse_loss_csv(&std::fs::read_to_string(out.join("loss.csv")).unwrap_or_default());
        log.retain(|r| r.step <= state.step);
        metrics = parse_metrics_csv(&std::fs::read_to_string(out.join("metrics.csv")).unwrap_or_default());
        metrics.retain(|r| r.epoch <= state.epoch);
        start_step = state.step;
        eprintln!("resuming {} at step {} (epoch {})", out.display(), state.step, state.epoch);
    }

    let t = &cfg.train;
    let epochs = t.steps.div_ceil(t.epoch_steps);
    eprintln!(
        "training on {} images, testing on {} (ready in {load_seconds:.2} s), with {}: {} steps = {epochs} epochs of \
         {} steps",
        samples.len(),
        test.len(),
        t.features,
        t.steps,
        t.epoch_steps
    );
    let bar = ProgressBar::new(t.steps as u64);
    bar.set_style(
        ProgressStyle::with_template("train [{bar:30}] {pos}/{len} steps {msg} eta {eta}")
            .expect("valid template")
            .progress_chars("=> "),
    );
    bar.set_position(start_step as u64);
    let mut write_error = None;
    let result = train(t, &samples, &test, &device(&cfg.device)?, resume_bytes.as_deref(), |report| {
        let r = &report.row;
        bar.set_position(r.step as u64);
        bar.set_message(format!(
            "epoch {} loss {:.4}, {:.2} steps/s",
            r.epoch,
            r.loss,
            (r.step - start_step) as f64 / r.seconds.max(1e-9)
        ));
        log.push(*r);
        if let Some((row, bytes)) = report.epoch {
            metrics.push(row);
            let saved = save_epoch(&out, &log, &metrics, &row, &bytes);
            if let Err(e) = saved {
                write_error = Some(e);
                return ControlFlow::Break(());
            }
        }
        ControlFlow::Continue(())
    });
    bar.finish_and_clear();
    if let Some(e) = write_error {
        return Err(e.context("saving a checkpoint; training stopped"));
    }
    let trained = match result {
        Ok(t) => t,
        Err(TrainError::Diverged { step, batch, cause, last_good }) => {
            let path = out.join("last_good.safetensors");
            write_file(&path, &last_good.weights)?;
            write_file(&out.join("loss.csv"), loss_csv(&log).as_bytes())?;
            let batch = name_batch(&batch, &names);
            bail!(
                "training diverged at step {step} on the batch [{batch}]: {cause}. The weights from before that \
                 step are in {}, the last epoch's checkpoint in {}; try a lower --lr (now {}) or --clip-grad-norm",
                path.display(),
                last.display(),
                t.lr
            );
        }
        Err(e) => return Err(e.into()),
    };
    let model = out.join("model.safetensors");
    write_file(&model, &trained.weights)?;
    let steps_done = trained.log.len();
    let summary = serde_json::json!({
        "steps": steps_done,
        "seconds": trained.seconds,
        "steps_per_second": steps_done as f64 / trained.seconds.max(1e-9),
        "loader_share": trained.loader_seconds / trained.seconds.max(1e-9),
        "final_loss": log.last().map(|r| r.loss),
        "best": metrics.iter().rev().find(|r| r.best).map(|r| serde_json::json!({"epoch": r.epoch, "test_loss": r.test_loss})),
        "threads": std::env::var("RAYON_NUM_THREADS").ok(),
        "load_seconds": load_seconds,
    });
    write_file(&out.join("summary.json"), serde_json::to_string_pretty(&summary)?.as_bytes())?;
    let first = log.first().map(|r| r.loss).unwrap_or(f64::NAN);
    let final_loss = log.last().map(|r| r.loss).unwrap_or(f64::NAN);
    let test_note = match metrics.iter().rev().find(|r| r.best) {
        Some(b) => format!("; best test loss {:.4} at epoch {}", b.test_loss.unwrap_or(f64::NAN), b.epoch),
        None => String::new(),
    };
    eprintln!(
        "trained {} steps: loss {first:.4} → {final_loss:.4}{test_note}; {:.2} steps/s, the loader's share {:.1}%; \
         model {}",
        t.steps,
        steps_done as f64 / trained.seconds.max(1e-9),
        100.0 * trained.loader_seconds / trained.seconds.max(1e-9),
        model.display()
    );
    Ok(())
}

/// The end of an epoch on disk: the logs first, then the checkpoints, the plot, and last the resume point
/// `checkpoints/last.safetensors` (each file written atomically), so a killed run resumes from a
/// consistent epoch and drops the log rows after it.
fn save_epoch(out: &Path, log: &[LossRow], metrics: &[EpochRow], row: &EpochRow, bytes: &[u8]) -> Result<()> {
    write_file(&out.join("loss.csv"), loss_csv(log).as_bytes())?;
    write_file(&out.join("metrics.csv"), metrics_csv(metrics).as_bytes())?;
    if row.test_loss.is_some() {
        write_file(&out.join("checkpoints").join(format!("epoch_{:04}.safetensors", row.epoch)), bytes)?;
        let png = plot_losses(metrics, 800, 500).map_err(anyhow::Error::msg)?;
        write_file(&out.join(LOSS_PLOT), &png)?;
    }
    if row.best {
        write_file(&out.join("best.safetensors"), bytes)?;
    }
    write_file(&out.join("checkpoints").join("last.safetensors"), bytes)
}

/// `sample 3 at (...)` → `cbox_v001@4spp at (...)`.
fn name_batch(batch: &str, names: &[String]) -> String {
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
    use std::cell::Cell;

    use hush_dataset::Image;
    use hush_train::TrainSample;

    use super::{TrainArgs, cached_samples, resolve};

    fn samples(value: f32) -> Vec<TrainSample> {
        let input = Image::from_fn(4, 4, 9, |x, y, c| value + 0.01 * (x + 2 * y + c) as f32);
        let target = Image::from_fn(4, 4, 3, |x, _, _| value + 0.1 * x as f32);
        vec![TrainSample { input, target }]
    }

    /// Resuming keeps the run's network when the options repeat its kind without a width: a patch MLP
    /// trained at width 0.0625 stays at 0.0625 (it used to fall back to the default 0.25 and be refused as a
    /// changed network); a new width or kind is a new network.
    #[test]
    fn resuming_with_the_same_arch_keeps_the_network() {
        let args = |arch: &str, width: Option<f64>| TrainArgs {
            arch: Some(arch.into()),
            width,
            dataset: Some("ds".into()),
            ..Default::default()
        };
        let base = resolve(&args("patch_mlp", Some(0.0625)), None, 8).unwrap();
        let resumed = resolve(&args("patch_mlp", None), Some(&base), 8).unwrap();
        assert_eq!(resumed.train.net, base.train.net);
        let wider = resolve(&args("patch_mlp", Some(0.125)), Some(&base), 8).unwrap();
        assert_ne!(wider.train.net, base.train.net);
        let unet = resolve(&args("unet", None), Some(&base), 8).unwrap();
        assert!(unet.train.net.as_unet().is_some());
    }

    /// A missing, stale or damaged cache is rebuilt and rewritten; an intact one is read without preparing
    /// anything; a run gets the same values either way.
    #[test]
    fn the_sample_cache_is_rebuilt_unless_intact() {
        let dir = std::env::temp_dir().join(format!("hush-sample-cache-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let path = dir.join("cache").join("train.f16");
        let builds = Cell::new(0);
        let load = |key: &str, value: f32| {
            cached_samples(&path, key, || {
                builds.set(builds.get() + 1);
                Ok(samples(value))
            })
            .unwrap()
        };
        let fresh = load("a", 0.25);
        assert_eq!(builds.get(), 1);
        assert!(path.is_file(), "the cache is written");
        assert_eq!(load("a", 0.25), fresh, "read back: the same values");
        assert_eq!(builds.get(), 1, "an intact cache is trusted");

        // Damaged (one byte changed), then cut short: prepared again, not trusted.
        let mut bytes = std::fs::read(&path).unwrap();
        bytes[40] ^= 1;
        std::fs::write(&path, &bytes).unwrap();
        assert_eq!(load("a", 0.25), fresh);
        assert_eq!(builds.get(), 2);
        std::fs::write(&path, &bytes[..bytes.len() / 2]).unwrap();
        assert_eq!(load("a", 0.25), fresh);
        assert_eq!(builds.get(), 3);
        assert_eq!(load("a", 0.25), fresh);
        assert_eq!(builds.get(), 3, "the rebuilt cache is intact again");

        // Another key (the dataset or the settings changed): the new data, not the cached one.
        let other = load("b", 0.5);
        assert_eq!(builds.get(), 4);
        assert_ne!(other, fresh);
        let _ = std::fs::remove_dir_all(&dir);
    }
}
