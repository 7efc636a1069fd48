//! The options of a training run, their defaults, and the [`RunConfig`] they resolve to.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use hush_dataset::AuxSource;
use hush_net::{
    Activation, Head, InputFeatures, Loss, LossSpace, MAX_KERNEL, NetConfig, PatchMlpConfig, Pretrained, UNetConfig,
    UNetKind,
};
use hush_train::{Augment, InitRecord, OptimizerConfig, Schedule, TrainConfig};
use serde::{Deserialize, Serialize};

/// The input features when none are given.
pub const DEFAULT_FEATURES: &str = "color,albedo,normal";
/// The width multiplier of a U-Net when none is given (OIDN's widths are 1.0).
pub const DEFAULT_WIDTH: f64 = 0.25;
/// The device when none is given.
pub const DEFAULT_DEVICE: &str = "cpu";
/// The learning rate of a run that starts from trained weights (`--init`) when none is given: a tenth of
/// [`defaults`]' 1e-3, which would first undo much of what the weights know.
pub const DEFAULT_FINETUNE_LR: f64 = 1e-4;

/// The training configuration of a run that gives no options but its features: the thesis's recipe
/// ([`TrainConfig::thesis`]: the MIX loss, Adam, a constant schedule, PU transfer, flips, batch 4) sized for a
/// small machine: a U-Net at [`DEFAULT_WIDTH`], 64² crops, 300 steps at a learning rate of 1e-3 (the thesis's
/// 1e-4 is for its 1270 epochs), one pass over the training images per epoch, the test loss every 10 epochs.
pub fn defaults(features: InputFeatures) -> TrainConfig {
    let net = UNetConfig::new(UNetKind::Unet, features.in_channels(), DEFAULT_WIDTH);
    TrainConfig {
        net: net.into(),
        lr: 1e-3,
        steps: 300,
        epoch_steps: 0,
        crop: 64,
        eval_every: 10,
        ..TrainConfig::thesis(features)
    }
}

/// The options of a training run, as `hush train` takes them. Every option can also be set in a `--config`
/// TOML file under the flag's name (`eval-every = 5`); options given override the file ([`TrainOptions::or`]).
/// What is not given comes from the run being resumed, or else from [`defaults`].
#[derive(Clone, Debug, Default, PartialEq, Deserialize)]
#[cfg_attr(feature = "clap", derive(clap::Args))]
#[serde(deny_unknown_fields, rename_all = "kebab-case")]
pub struct TrainOptions {
    /// TOML file with any of the options below, named as the flags (`lr = 1e-4`, `features = "dsnn"`).
    #[cfg_attr(feature = "clap", arg(long))]
    #[serde(skip)]
    pub config: Option<PathBuf>,
    /// Continue the run in this folder exactly where it stopped (from its last checkpoint and
    /// config.json). Only --steps, --epochs, --eval-every and --device may change.
    #[cfg_attr(feature = "clap", arg(long))]
    #[serde(skip)]
    pub resume: Option<PathBuf>,
    /// Start from trained weights (fine-tuning): `oidn` (OIDN 2.5.1's official weights for --features, built
    /// in), an OIDN `.tza` file or a hush `model.safetensors`. The network, its width, features and transfer
    /// come from the weights; more --features than they take start at zero weights; --lr defaults to 1e-4.
    #[cfg_attr(feature = "clap", arg(long))]
    pub init: Option<PathBuf>,
    /// Dataset folder (from `hush dataset`): its training split is trained on, its test split measured.
    #[cfg_attr(feature = "clap", arg(long))]
    pub dataset: Option<PathBuf>,
    /// Training scenes (by name) held out as the validation split: not trained on, their views give the test
    /// loss, best.safetensors and the choice of a run's length, and the dataset's test split is not read.
    #[cfg_attr(feature = "clap", arg(long, value_delimiter = ','))]
    pub validation: Option<Vec<String>>,
    /// Training scenes (by name; `prefix*` for every scene whose name starts so) that the run leaves out: not
    /// trained on, not validated on. One dataset then serves models trained on different scene sets.
    #[cfg_attr(feature = "clap", arg(long, value_delimiter = ','))]
    pub exclude: Option<Vec<String>>,
    /// Run folder: config.json, loss.csv, metrics.csv, checkpoints/, best.safetensors, model.safetensors.
    #[cfg_attr(feature = "clap", arg(long))]
    pub out: Option<PathBuf>,
    /// Input features: `color`, `color,albedo,normal` or `color,diffuse,specular,normal`, or the thesis's
    /// names M_n, M_ann, M_dsnn [default: color,albedo,normal].
    #[cfg_attr(feature = "clap", arg(long))]
    pub features: Option<String>,
    /// Auxiliary inputs: `noisy` (each noisy render's own, at its spp: what a user denoising a render has) or
    /// `clean` (the view's, rendered once at the dataset's --aux-spp) [default: noisy].
    #[cfg_attr(feature = "clap", arg(long))]
    pub aux: Option<String>,
    /// Noisy images of these spp are the inputs (all of them if not given).
    #[cfg_attr(feature = "clap", arg(long, value_delimiter = ','))]
    pub spp: Option<Vec<u32>>,
    /// Network: unet (OIDN's), unet_small, unet_large, autoencoder (the thesis's M_DAE), or patch_mlp (Burger et
    /// al.'s MLP on 17×17 patches at stride 3, tanh; patch_mlp_relu with ReLU) [default: unet].
    #[cfg_attr(feature = "clap", arg(long))]
    pub arch: Option<String>,
    /// What the U-Net's output layer predicts: direct (the denoised color, as OIDN's networks) or kernel:K
    /// (per pixel, normalized weights of the K×K neighbourhood of the noisy color, K odd, 3 to 21: kernel
    /// prediction, Bako et al. 2017; `kernel` is 5×5). With --init, the weights' encoder and decoder are kept
    /// and the kernel layer starts at zero [default: direct, or the resumed run's].
    #[cfg_attr(feature = "clap", arg(long))]
    pub head: Option<String>,
    /// Where a kernel head averages the noisy color: transfer (in the network's transfer space, as KPCN
    /// averages its log-transformed input) or linear (in linear light: the transfer's inverse, the average, the
    /// transfer again; no Jensen bias at low spp) [default: transfer, or the resumed run's].
    #[cfg_attr(feature = "clap", arg(long))]
    pub kernel_space: Option<String>,
    /// Width multiplier of the network (1.0 = OIDN's widths; the thesis's M1 0.66, M2 0.33; for patch_mlp, of
    /// four hidden layers of 2047 units) [default: 0.25].
    #[cfg_attr(feature = "clap", arg(long))]
    pub width: Option<f64>,
    /// Loss: l1, mse, ssim, msssim, mix (0.16·L1 + 0.84·(1 − MS-SSIM)), mape, smape, l1_grad, log_mse (the mean
    /// over images of ln(1 + MSE/1e-5): a mean PSNR's objective) [default: mix].
    #[cfg_attr(feature = "clap", arg(long))]
    pub loss: Option<String>,
    /// Where the loss compares output and target: transfer (in the network's transfer space, PU for HDR
    /// color: OIDN's choice) or tonemapped (through OIDN's evaluation tonemap, filmic and sRGB, at the
    /// reference's exposure: where hush eval measures PSNR) [default: transfer].
    #[cfg_attr(feature = "clap", arg(long))]
    pub loss_space: Option<String>,
    /// Add this weight times the colour-mean term: per crop and channel, the squared relative difference
    /// between the output's and the reference's image means on the evaluation's display images (what the colour-cast
    /// guard measures), which per-pixel losses leave free [default: 0, none].
    #[cfg_attr(feature = "clap", arg(long))]
    pub color_mean: Option<f64>,
    /// Optimizer: adam, adamw (decoupled weight decay 0.01), sgd, sgd_momentum (0.9) [default: adam].
    #[cfg_attr(feature = "clap", arg(long))]
    pub optimizer: Option<String>,
    /// Base learning rate (for one_cycle its maximum) [default: 1e-3].
    #[cfg_attr(feature = "clap", arg(long))]
    pub lr: Option<f64>,
    /// Learning-rate schedule per epoch: constant, step[:every:gamma], lambda:f1,f2,..., exponential[:gamma],
    /// cosine[:min_lr], sgdr[:t0:t_mult], one_cycle [default: constant].
    #[cfg_attr(feature = "clap", arg(long))]
    pub schedule: Option<String>,
    /// Train this many epochs (instead of --steps).
    #[cfg_attr(feature = "clap", arg(long, conflicts_with = "steps"))]
    pub epochs: Option<usize>,
    /// Optimizer steps in total [default: 300].
    #[cfg_attr(feature = "clap", arg(long))]
    pub steps: Option<usize>,
    /// Steps per epoch [default: one pass over the training images, ⌈images / batch⌉].
    #[cfg_attr(feature = "clap", arg(long))]
    pub epoch_steps: Option<usize>,
    /// Batch size [default: 4].
    #[cfg_attr(feature = "clap", arg(long))]
    pub batch: Option<usize>,
    /// Square crop size, a multiple of 16 (the thesis: 256) [default: 64].
    #[cfg_attr(feature = "clap", arg(long))]
    pub crop: Option<usize>,
    /// Augmentation: crop (random crops only), flips (and 8 orientations), full (and OIDN's channel
    /// permutations), oidn (and OIDN's shrunk, zero-padded crops and zeroed samples) [default: flips].
    #[cfg_attr(feature = "clap", arg(long))]
    pub augment: Option<String>,
    /// Seed of the initial weights and of the crops [default: 0].
    #[cfg_attr(feature = "clap", arg(long))]
    pub seed: Option<u64>,
    /// Every N epochs: test loss, checkpoints/epoch_N.safetensors, the loss plot [default: 10].
    #[cfg_attr(feature = "clap", arg(long, alias = "checkpoint-every"))]
    pub eval_every: Option<usize>,
    /// Clip the gradients' global L2 norm to this.
    #[cfg_attr(feature = "clap", arg(long))]
    pub clip_grad_norm: Option<f64>,
    /// Train only these layers (e.g. `enc_conv0,dec_conv0`); the others keep their weights [default: all].
    #[cfg_attr(feature = "clap", arg(long, value_delimiter = ','))]
    pub trainable: Option<Vec<String>>,
    /// cpu, or cuda when built with `--features cuda` [default: cpu].
    #[cfg_attr(feature = "clap", arg(long))]
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
    /// Which auxiliary images go with each noisy input; runs from before the choice trained on the clean ones.
    #[serde(default = "clean_aux")]
    pub aux: AuxSource,
    /// Training scenes held out as the validation split (empty: the test loss is the test split's).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub validation: Vec<String>,
    /// Training scenes (names or `prefix*` patterns) the run leaves out (empty: none).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub exclude: Vec<String>,
    pub train: TrainConfig,
}

fn clean_aux() -> AuxSource {
    AuxSource::Clean
}

/// Parses `--aux`.
pub fn parse_aux(s: &str) -> Result<AuxSource> {
    AuxSource::parse(s).with_context(|| format!("unknown --aux '{s}': use noisy or clean"))
}

impl TrainOptions {
    /// Fills every option not given here from `file`.
    pub fn or(self, file: TrainOptions) -> TrainOptions {
        macro_rules! merge {
            ($($f:ident),*) => { TrainOptions { config: self.config, resume: self.resume, $($f: self.$f.or(file.$f)),* } };
        }
        merge!(
            init,
            aux,
            dataset,
            validation,
            exclude,
            out,
            features,
            spp,
            arch,
            head,
            kernel_space,
            width,
            loss,
            loss_space,
            color_mean,
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
            trainable,
            device
        )
    }
}

impl TrainOptions {
    /// Reads options from a TOML file whose keys are the flags' names (`lr = 1e-4`, `eval-every = 5`).
    pub fn from_toml_file(path: &Path) -> Result<TrainOptions> {
        let text = std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
        toml::from_str(&text).with_context(|| format!("parsing {}", path.display()))
    }

    /// These options with those of their `config` file (if any) filling in what is not given.
    pub fn with_config_file(self) -> Result<TrainOptions> {
        match &self.config {
            Some(path) => {
                let file = TrainOptions::from_toml_file(path)?;
                Ok(self.or(file))
            }
            None => Ok(self),
        }
    }
}

/// The thesis's feature-set names as aliases of feature lists.
pub fn parse_features(s: &str) -> Result<InputFeatures> {
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
            Arch::UNet(kind) => UNetConfig::new(kind, in_channels, width).into(),
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

pub fn parse_loss(s: &str) -> Result<Loss> {
    Loss::parse(s)
        .with_context(|| format!("unknown loss '{s}': use l1, mse, ssim, msssim, mix, mape, smape, l1_grad or log_mse"))
}

/// `--init`'s name for OIDN's official weights built into hush ([`crate::official`]).
pub const INIT_OIDN: &str = "oidn";

/// Reads the trained weights of `--init` and their record: a file, or [`INIT_OIDN`] for OIDN's official
/// weights of `features` (those with albedo and normal when OIDN has none of exactly these features).
pub fn read_init(init: &Path, features: Option<&InputFeatures>) -> Result<(Pretrained, InitRecord)> {
    read_trained(init, features, "--init")
}

/// [`read_init`] for any option that names trained weights (`flag`, which its errors name).
pub(crate) fn read_trained(
    init: &Path,
    features: Option<&InputFeatures>,
    flag: &str,
) -> Result<(Pretrained, InitRecord)> {
    let (name, bytes) = match init.to_str().and_then(|s| s.strip_prefix(INIT_OIDN)) {
        Some(rest) if rest.is_empty() || rest.starts_with('-') => {
            let official = match rest.strip_prefix(&format!("-{}", crate::official::OIDN_VERSION)) {
                Some(name) if !name.is_empty() => crate::official::official(name.trim_start_matches(' '))
                    .with_context(|| format!("{flag} {}: no such official OIDN weights", init.display()))?,
                _ => crate::official::official_for(features.unwrap_or(&parse_features(DEFAULT_FEATURES)?)),
            };
            (official.method_name(), std::borrow::Cow::Borrowed(official.bytes))
        }
        _ => {
            let bytes = crate::read_weight_file(init).with_context(|| {
                format!("reading {flag} {} (a .tza or .safetensors file, or `{INIT_OIDN}`)", init.display())
            })?;
            (init.display().to_string(), std::borrow::Cow::Owned(bytes))
        }
    };
    let weights = Pretrained::read(&bytes, &candle_core::Device::Cpu)
        .with_context(|| format!("{flag} {name}: not weights hush can read"))?;
    let record = InitRecord::of(name, &bytes, weights.info.features.clone());
    Ok((weights, record))
}

/// Builds the run's configuration from the options, taking what they do not give from `base` (the run
/// being resumed), the `--init` weights (read here) or else the defaults; `train_images` sizes an epoch.
///
/// ```
/// use hush_pipeline::TrainOptions;
/// use hush_pipeline::train::{defaults, parse_features, resolve};
///
/// let options = TrainOptions { dataset: Some("ds".into()), lr: Some(1e-4), ..Default::default() };
/// let run = resolve(&options, None, 10).unwrap();
/// let features = parse_features("color,albedo,normal").unwrap();
/// // What was not given is the default; an epoch is one pass over the 10 images in batches of 4.
/// assert_eq!(run.train, hush_train::TrainConfig { lr: 1e-4, epoch_steps: 3, ..defaults(features) });
/// // Resuming that run with a new budget keeps everything else.
/// let more = TrainOptions { steps: Some(900), ..Default::default() };
/// assert_eq!(resolve(&more, Some(&run), 10).unwrap().train.lr, 1e-4);
/// ```
pub fn resolve(args: &TrainOptions, base: Option<&RunConfig>, train_images: usize) -> Result<RunConfig> {
    resolve_with_init(args, base, train_images).map(|(cfg, _)| cfg)
}

/// [`resolve`], handing back the `--init` weights it read (when the options name some), so that a run
/// reads them once.
pub fn resolve_with_init(
    args: &TrainOptions,
    base: Option<&RunConfig>,
    train_images: usize,
) -> Result<(RunConfig, Option<Pretrained>)> {
    let b = base.map(|c| &c.train);
    let asked = args.features.as_deref().map(parse_features).transpose()?;
    let init = match &args.init {
        Some(path) => Some(read_init(path, asked.as_ref().or(b.map(|b| &b.features)))?),
        None => None,
    };
    let init_features = init.as_ref().map(|(w, _)| w.info.features.clone());
    let features = match asked {
        Some(f) => f,
        None => match (b, init_features) {
            (Some(b), _) => b.features.clone(),
            (None, Some(f)) => f,
            (None, None) => parse_features(DEFAULT_FEATURES)?,
        },
    };
    // What an option not given takes: the run being resumed, the initial weights, or else the defaults.
    let d = match (b, &init) {
        (Some(b), _) => b.clone(),
        (None, Some((w, record))) => TrainConfig {
            net: w.info.net.with_in_channels(features.in_channels()),
            transfer: w.info.transfer,
            lr: DEFAULT_FINETUNE_LR,
            init: Some(record.clone()),
            ..defaults(features.clone())
        },
        (None, None) => defaults(features.clone()),
    };
    let base_arch = match &d.net {
        NetConfig::PatchMlp(c) => Arch::PatchMlp(c.activation),
        NetConfig::UNet(c) => Arch::UNet(c.kind),
    };
    let arch = match &args.arch {
        Some(a) => parse_arch(a)?,
        None => base_arch,
    };
    let net = match args.width {
        // Resuming (or starting from trained weights) with that network's kind and no new width: the
        // network as it was (an MLP's hidden sizes, σ and patch included), whatever repeats its `--arch`.
        None if base_arch == arch && (b.is_some() || init.is_some()) => d.net.with_in_channels(features.in_channels()),
        width => {
            let base_width = d.net.as_unet().map(|c| c.width);
            arch.config(features.in_channels(), width.or(base_width).unwrap_or(DEFAULT_WIDTH))
        }
    };
    let net = match &args.head {
        Some(h) => {
            let head = Head::parse(h).with_context(|| {
                format!("unknown --head '{h}': use direct or kernel:K with K odd, 3 to {MAX_KERNEL}")
            })?;
            match &net {
                NetConfig::UNet(c) => c.with_head(head).into(),
                NetConfig::PatchMlp(_) if head.is_direct() => net,
                NetConfig::PatchMlp(_) => {
                    bail!("--head {h}: only a U-Net predicts kernels; the patch MLP predicts colors")
                }
            }
        }
        None => match &net {
            // A new network (--arch or --width) keeps the head of the run it resumes or the weights it starts from.
            NetConfig::UNet(c) if d.net.head() != c.head => c.with_head(d.net.head()).into(),
            _ => net,
        },
    };
    let net = match (&net, args.kernel_space.as_deref()) {
        (NetConfig::UNet(c), space) => {
            let linear = match space {
                Some("linear") => Some(d.transfer),
                Some("transfer") => None,
                Some(other) => bail!("unknown --kernel-space '{other}': use transfer or linear"),
                // The resumed run's (or the starting weights'), while the network still predicts kernels.
                None => d.net.as_unet().and_then(|b| b.kernel_linear).filter(|_| !c.head.is_direct()),
            };
            if linear.is_some() && c.head.is_direct() {
                bail!(
                    "--kernel-space linear: only a kernel-predicting network (--head kernel:K) averages the noisy color"
                )
            }
            c.with_kernel_linear(linear).into()
        }
        (NetConfig::PatchMlp(_), Some(s)) => {
            bail!("--kernel-space {s}: only a kernel-predicting U-Net averages the noisy color")
        }
        (NetConfig::PatchMlp(_), None) => net,
    };
    let optimizer = match &args.optimizer {
        Some(o) => OptimizerConfig::parse(o)
            .with_context(|| format!("unknown --optimizer '{o}': use adam, adamw, sgd or sgd_momentum"))?,
        None => d.optimizer.clone(),
    };
    let augment = match &args.augment {
        Some(a) => {
            Augment::parse(a).with_context(|| format!("unknown --augment '{a}': use crop, flips, full or oidn"))?
        }
        None => d.augment,
    };
    let loss = match &args.loss {
        Some(l) => parse_loss(l)?,
        None => d.loss,
    };
    let loss_space = match &args.loss_space {
        Some(l) => {
            LossSpace::parse(l).with_context(|| format!("unknown --loss-space '{l}': use transfer or tonemapped"))?
        }
        None => d.loss_space,
    };
    let batch = args.batch.unwrap_or(d.batch);
    let epoch_steps = args
        .epoch_steps
        .or((d.epoch_steps > 0).then_some(d.epoch_steps))
        .unwrap_or(train_images.div_ceil(batch.max(1)).max(1));
    let steps = match args.epochs {
        Some(e) => e * epoch_steps,
        None => args.steps.unwrap_or(d.steps),
    };
    let epochs = steps.div_ceil(epoch_steps.max(1));
    let schedule = match &args.schedule {
        Some(s) => Schedule::parse(s, epochs).with_context(|| {
            format!(
                "unknown --schedule '{s}': use constant, step[:every:gamma], lambda:f1,f2,..., \
                 exponential[:gamma], cosine[:min_lr], sgdr[:t0:t_mult] or one_cycle"
            )
        })?,
        None => d.schedule.clone(),
    };
    let device = args.device.clone().or(base.map(|c| c.device.clone())).unwrap_or_else(|| DEFAULT_DEVICE.into());
    if !crate::is_known_device(&device) {
        bail!("unknown --device '{device}': use cpu or cuda");
    }
    let train = TrainConfig {
        features,
        transfer: d.transfer,
        net,
        loss,
        loss_space,
        color_mean: args.color_mean.unwrap_or(d.color_mean),
        optimizer,
        lr: args.lr.unwrap_or(d.lr),
        schedule,
        steps,
        epoch_steps,
        batch,
        crop: args.crop.unwrap_or(d.crop),
        augment,
        seed: args.seed.unwrap_or(d.seed),
        eval_every: args.eval_every.unwrap_or(d.eval_every),
        clip_grad_norm: args.clip_grad_norm.or(d.clip_grad_norm),
        trainable: args.trainable.clone().unwrap_or(d.trainable.clone()),
        // The same weights named by another path are the same start.
        init: match (&init, &d.init) {
            (Some((_, now)), Some(then)) if now.fnv1a == then.fnv1a => Some(then.clone()),
            (Some((_, now)), _) => Some(now.clone()),
            (None, then) => then.clone(),
        },
    };
    if let Some((weights, record)) = &init {
        // The network is the one the weights are; --arch and --width may only repeat it.
        let adapted = weights
            .adapt(&train.features)
            .and_then(|w| w.with_head(train.net.head()))
            .with_context(|| format!("--init {}", record.source))?;
        // Where the kernels average has no weights: the options decide it.
        if adapted.info.net.with_kernel_linear(train.net.kernel_linear()) != train.net {
            bail!(
                "--init {} holds a {}, but the options ask for a {}; drop --arch and --width to train the \
                 network the weights are",
                record.source,
                adapted.info.net.describe(),
                train.net.describe()
            );
        }
    }
    train.validate()?;
    let dataset = args
        .dataset
        .clone()
        .or(base.map(|c| c.dataset.clone()))
        .context("--dataset is required (or `dataset = ...` in --config)")?;
    let spp = args.spp.clone().or(base.map(|c| c.spp.clone())).unwrap_or_default();
    let aux = match &args.aux {
        Some(a) => parse_aux(a)?,
        None => base.map_or(AuxSource::default(), |c| c.aux),
    };
    let validation = args.validation.clone().or(base.map(|c| c.validation.clone())).unwrap_or_default();
    let exclude = args.exclude.clone().or(base.map(|c| c.exclude.clone())).unwrap_or_default();
    Ok((RunConfig { dataset, spp, device, aux, validation, exclude, train }, init.map(|(weights, _)| weights)))
}

#[cfg(test)]
mod tests {
    use super::{TrainOptions, resolve};

    /// Resuming keeps the run's network when the options repeat its kind without a width: a patch MLP
    /// trained at width 0.0625 stays at 0.0625 (it used to fall back to the default 0.25 and be refused as a
    /// changed network); a new width or kind is a new network.
    #[test]
    fn resuming_with_the_same_arch_keeps_the_network() {
        let args = |arch: &str, width: Option<f64>| TrainOptions {
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

    /// `--color-mean W` (on the command line or in a `--config` file) reaches the run's configuration; a
    /// resumed run keeps its weight; a negative one is refused.
    #[test]
    fn the_color_mean_option_reaches_the_run() {
        let opts = |w: Option<f64>| TrainOptions { color_mean: w, dataset: Some("ds".into()), ..Default::default() };
        let run = resolve(&opts(Some(0.5)), None, 8).unwrap();
        assert_eq!(run.train.color_mean, 0.5);
        assert_eq!(resolve(&opts(None), Some(&run), 8).unwrap().train.color_mean, 0.5);
        assert_eq!(resolve(&opts(None), None, 8).unwrap().train.color_mean, 0.0);
        let file: TrainOptions = toml::from_str("color-mean = 2.0").unwrap();
        assert_eq!(file.color_mean, Some(2.0));
        let err =
            format!("{:#}", resolve(&opts(Some(-1.0)), None, 8).and_then(|r| Ok(r.train.validate()?)).unwrap_err());
        assert!(err.contains("colour-mean"), "{err}");
    }

    /// `--head kernel:K` makes the U-Net predict kernels, from OIDN's weights too (whose direct output
    /// layer it replaces); a resumed run keeps its head, also under a new width; the patch MLP and
    /// malformed kernels are refused naming what is allowed.
    #[test]
    fn the_head_option_sets_kernel_prediction() {
        use hush_net::Head;
        let opts = |head: Option<&str>, width: Option<f64>, init: bool| TrainOptions {
            head: head.map(Into::into),
            width,
            init: init.then(|| "oidn".into()),
            dataset: Some("ds".into()),
            ..Default::default()
        };
        let head = |o: &TrainOptions, base| resolve(o, base, 8).map(|r| r.train.net.head());
        let kpn = resolve(&opts(Some("kernel:7"), None, true), None, 8).unwrap();
        assert_eq!(kpn.train.net.head(), Head::Kernel { size: 7 });
        assert_eq!(kpn.train.net.as_unet().map(|c| c.width), Some(1.0), "OIDN's network, its head replaced");
        assert_eq!(head(&opts(None, None, false), Some(&kpn)).unwrap(), Head::Kernel { size: 7 });
        assert_eq!(head(&opts(None, Some(0.5), false), Some(&kpn)).unwrap(), Head::Kernel { size: 7 });
        assert_eq!(head(&opts(Some("direct"), None, false), None).unwrap(), Head::Direct);
        for bad in ["kernel:4", "kernel:23", "gaussian"] {
            let err = format!("{:#}", resolve(&opts(Some(bad), None, false), None, 8).unwrap_err());
            assert!(err.contains("use direct or kernel:K"), "{bad}: {err}");
        }
        let mlp = TrainOptions { arch: Some("patch_mlp".into()), ..opts(Some("kernel:5"), None, false) };
        let err = format!("{:#}", resolve(&mlp, None, 8).unwrap_err());
        assert!(err.contains("only a U-Net predicts kernels"), "{err}");
    }

    /// `--kernel-space linear` makes the kernels average in linear light through the run's transfer, from
    /// OIDN's weights too; a resumed run keeps it (under a new width too) unless told `transfer`, and loses it
    /// with a direct head; a direct network or an unknown space is refused.
    #[test]
    fn the_kernel_space_option_averages_in_linear_light() {
        use hush_net::transfer::Transfer;
        let opts = |head: Option<&str>, space: Option<&str>, width: Option<f64>, init: bool| TrainOptions {
            head: head.map(Into::into),
            kernel_space: space.map(Into::into),
            width,
            init: init.then(|| "oidn".into()),
            dataset: Some("ds".into()),
            ..Default::default()
        };
        let space = |o: &TrainOptions, base| resolve(o, base, 8).map(|r| r.train.net.kernel_linear());
        let linear = resolve(&opts(Some("kernel:5"), Some("linear"), None, true), None, 8).unwrap();
        assert_eq!(linear.train.net.kernel_linear(), Some(Transfer::Pu));
        assert_eq!(linear.train.transfer, Transfer::Pu);
        assert_eq!(space(&opts(Some("kernel:5"), None, None, false), None).unwrap(), None, "transfer by default");
        assert_eq!(space(&opts(None, None, None, false), Some(&linear)).unwrap(), Some(Transfer::Pu));
        assert_eq!(space(&opts(None, None, Some(0.5), false), Some(&linear)).unwrap(), Some(Transfer::Pu));
        assert_eq!(space(&opts(None, Some("transfer"), None, false), Some(&linear)).unwrap(), None);
        assert_eq!(space(&opts(Some("direct"), None, None, false), Some(&linear)).unwrap(), None);
        let err = format!("{:#}", resolve(&opts(None, Some("linear"), None, false), None, 8).unwrap_err());
        assert!(err.contains("only a kernel-predicting network"), "{err}");
        let err = format!("{:#}", resolve(&opts(Some("kernel:5"), Some("log"), None, false), None, 8).unwrap_err());
        assert!(err.contains("use transfer or linear"), "{err}");
    }
}
