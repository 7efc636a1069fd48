//! `hush bench`: the measurements behind `cargo xtask bench net`, one per process so that each
//! reports its own peak memory. Each prints one JSON object on stdout.
//!
//! - `inference`: the whole inference path of `hush denoise` ([`hush_pipeline::Denoiser`]: autoexposure,
//!   input transfer, the network on the zero-padded image, output transfer) on a synthetic image, warm
//!   median of N, with given weights (`--weights`) or randomly initialized ones.
//! - `train-step`: one training step as `hush train` takes it (forward, loss, backward, optimizer
//!   step) on a synthetic batch, warm median of N, and its achieved GFLOP/s.
//! - `gemm`: Candle's f32 matrix product on square matrices, the machine's reference rate.
//!
//! Without `--weights`, weights are randomly initialized: dense convolutions cost the same whatever the
//! values.

use anyhow::{Result, bail};
use candle_core::{DType, Device, Tensor};
use candle_nn::{VarBuilder, VarMap};
use clap::{Args, Subcommand};
use hush_net::{InputFeatures, Loss, ModelInfo, Net, UNetConfig, UNetKind, init_weights, transfer::Transfer};
use hush_train::{Optimizer, OptimizerConfig};

use hush_pipeline::process::{cpu_seconds, peak_rss_bytes};

#[derive(Args, Debug)]
pub struct BenchArgs {
    #[command(subcommand)]
    pub what: BenchWhat,
    /// Where the network runs: cpu or cuda [default: cuda when hush is built with it, else cpu].
    #[arg(long, global = true)]
    pub device: Option<String>,
}

#[derive(Subcommand, Debug)]
pub enum BenchWhat {
    /// Denoise one synthetic image with given weights or a randomly initialized network.
    Inference(NetArgs),
    /// Training steps on a synthetic batch.
    TrainStep(NetArgs),
    /// Candle's f32 matrix product (size × size times size × size).
    Gemm {
        #[arg(long, default_value_t = 1024)]
        size: usize,
        #[arg(long, default_value_t = 5)]
        runs: usize,
    },
}

#[derive(Args, Debug)]
pub struct NetArgs {
    /// unet, unet_small, unet_large or autoencoder.
    #[arg(long, default_value = "unet")]
    pub kind: String,
    #[arg(long, default_value_t = 1.0)]
    pub width: f64,
    /// Auxiliary features besides the color, e.g. `alb,nrm` (9 channels) or `diff,spec,nrm` (12).
    #[arg(long, default_value = "alb,nrm")]
    pub features: String,
    /// Image side in pixels (a crop side for train-step); the width where --height is given.
    #[arg(long, default_value_t = 512)]
    pub size: usize,
    /// Image height for inference (default: --size, a square).
    #[arg(long)]
    pub height: Option<usize>,
    /// Inference with these weights (a hush `.safetensors` or OIDN `.tza`), loaded as `hush denoise
    /// --model` loads them, instead of a randomly initialized --kind.
    #[arg(long)]
    pub weights: Option<std::path::PathBuf>,
    /// Images per training batch (train-step only).
    #[arg(long, default_value_t = 4)]
    pub batch: usize,
    /// Timed runs after one warm-up run.
    #[arg(long, default_value_t = 3)]
    pub runs: usize,
}

impl NetArgs {
    fn info(&self) -> Result<ModelInfo> {
        let Some(kind) = UNetKind::parse(&self.kind) else {
            bail!("unknown --kind {:?}; known: unet, unet_small, unet_large, autoencoder", self.kind)
        };
        let features = InputFeatures::parse(&self.features)?;
        let net = UNetConfig::new(kind, features.in_channels(), self.width);
        let info = ModelInfo { net: net.into(), features, transfer: Transfer::Pu };
        info.validate()?;
        self.check_counts()?;
        Ok(info)
    }

    /// Sizes and counts of at least 1 (also where `--weights` replaces `--kind`, which [`Self::info`] reads).
    fn check_counts(&self) -> Result<()> {
        if self.size == 0 || self.height == Some(0) || self.runs == 0 || self.batch == 0 {
            bail!("--size, --height, --runs and --batch must be at least 1")
        }
        Ok(())
    }
}

/// A deterministic, noisy-looking, positive image of `channels` interleaved channels.
fn synthetic(size: usize, channels: usize, salt: u32) -> Vec<f32> {
    synthetic_rect(size, size, channels, salt)
}

/// [`synthetic`] of `width × height` pixels.
fn synthetic_rect(width: usize, height: usize, channels: usize, salt: u32) -> Vec<f32> {
    (0..width * height * channels)
        .map(|i| {
            let h = (i as u32 ^ salt).wrapping_mul(0x9E37_79B9).rotate_left(13).wrapping_mul(0x85EB_CA6B);
            (h >> 8) as f32 / (1u32 << 24) as f32
        })
        .collect()
}

fn median(mut xs: Vec<f64>) -> f64 {
    xs.sort_by(f64::total_cmp);
    xs[xs.len() / 2]
}

/// Runs `f` once to warm up, then `runs` times; returns the median wall and CPU seconds.
fn time(runs: usize, mut f: impl FnMut() -> Result<()>) -> Result<(f64, f64, Vec<f64>)> {
    f()?;
    let (mut wall, mut cpu) = (Vec::new(), Vec::new());
    for _ in 0..runs {
        let (t, c) = (std::time::Instant::now(), cpu_seconds());
        f()?;
        wall.push(t.elapsed().as_secs_f64());
        cpu.push(cpu_seconds() - c);
    }
    Ok((median(wall.clone()), median(cpu), wall))
}

fn threads() -> serde_json::Value {
    serde_json::json!({
        "rayon_num_threads": std::env::var("RAYON_NUM_THREADS").ok(),
        "available_parallelism": std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1),
    })
}

pub fn run(args: BenchArgs) -> Result<()> {
    let device = hush_pipeline::device(args.device.as_deref())?;
    let json = match args.what {
        BenchWhat::Inference(a) => inference(&a, &device)?,
        BenchWhat::TrainStep(a) => train_step(&a, &device)?,
        BenchWhat::Gemm { size, runs } => gemm(size, runs.max(1), &device)?,
    };
    println!("{}", serde_json::to_string_pretty(&json)?);
    Ok(())
}

fn new_net(info: &ModelInfo, device: &Device) -> Result<(VarMap, Net)> {
    let varmap = VarMap::new();
    let net = Net::new(VarBuilder::from_varmap(&varmap, DType::F32, device), &info.net)?;
    init_weights(&varmap, 1)?;
    Ok((varmap, net))
}

fn inference(a: &NetArgs, device: &Device) -> Result<serde_json::Value> {
    a.check_counts()?;
    let (width, height) = (a.size, a.height.unwrap_or(a.size));
    // Loaded from weight bytes as `hush denoise` loads a model: plain tensors, not training variables,
    // whose ops would record the graph and keep every activation alive until the output is dropped.
    let denoiser = match &a.weights {
        Some(path) => hush_pipeline::Denoiser::load_on(path, device)?,
        None => {
            let info = a.info()?;
            let (varmap, _) = new_net(&info, device)?;
            hush_pipeline::Denoiser::from_bytes_on(&hush_net::save_weights(&varmap, &info)?, false, device)?
        }
    };
    let info = denoiser.info.clone();
    let image = |salt| hush_dataset::Image::new(width, height, 3, synthetic_rect(width, height, 3, salt));
    let color = image(1)?;
    let aux: Vec<hush_dataset::Image> =
        (0..info.features.aux.len()).map(|i| image(2 + i as u32)).collect::<Result<_, _>>()?;
    let aux_refs: Vec<&hush_dataset::Image> = aux.iter().collect();
    let (seconds, cpu, all) = time(a.runs, || {
        denoiser.denoise(&color, &aux_refs)?;
        Ok(())
    })?;
    let align = |n: usize| n.div_ceil(hush_net::ALIGNMENT) * hush_net::ALIGNMENT;
    let flop = 2.0 * info.net.multiply_adds(align(height), align(width)) as f64;
    Ok(serde_json::json!({
        "what": "inference",
        "weights": a.weights.as_ref().map(|p| p.display().to_string()),
        "kind": info.net.kind_name(), "width": info.net.as_unet().map(|u| u.width),
        "in_channels": info.net.in_channels(),
        "size": a.size, "image_width": width, "image_height": height, "device": format!("{device:?}"),
        "direct_convolutions": hush_net::direct_conv_available(),
        "seconds": seconds, "cpu_seconds": cpu, "runs_seconds": all,
        "gflop": flop / 1e9, "gflops": flop / 1e9 / seconds,
        "peak_rss_bytes": peak_rss_bytes(), "threads": threads(),
    }))
}

fn train_step(a: &NetArgs, device: &Device) -> Result<serde_json::Value> {
    let info = a.info()?;
    let (varmap, net) = new_net(&info, device)?;
    let mut opt = Optimizer::for_varmap(OptimizerConfig::adam(), &varmap)?;
    let c = info.net.in_channels();
    let shape = (a.batch, c, a.size, a.size);
    let x = Tensor::from_vec(synthetic(a.size, a.batch * c, 7), shape, device)?;
    let y = Tensor::from_vec(synthetic(a.size, a.batch * 3, 8), (a.batch, 3, a.size, a.size), device)?;
    let loss = Loss::Mix;
    let (seconds, cpu, all) = time(a.runs, || {
        let out = candle_core::Module::forward(&net, &x)?;
        let l = loss.compute(&out, &y)?;
        let grads = l.backward()?;
        opt.step(&grads, 1e-4, 1.0)?;
        // A GPU runs the step asynchronously: the time is the step's only once it has finished.
        device.synchronize()?;
        Ok(())
    })?;
    let padded = a.size.div_ceil(hush_net::ALIGNMENT) * hush_net::ALIGNMENT;
    // Forward, input gradient and weight gradient each cost one forward pass of multiply-adds.
    let flop = 3.0 * 2.0 * a.batch as f64 * info.net.multiply_adds(padded, padded) as f64;
    Ok(serde_json::json!({
        "what": "train-step",
        "kind": info.net.kind_name(), "width": info.net.as_unet().map(|u| u.width), "in_channels": c,
        "batch": a.batch, "size": a.size, "loss": loss.name(), "optimizer": "adam", "device": format!("{device:?}"),
        "seconds": seconds, "cpu_seconds": cpu, "runs_seconds": all,
        "flop_model": "3 forward passes of 3x3-convolution multiply-adds (forward, input gradient, weight gradient), \
                       2 FLOP each; loss, pooling and optimizer not counted",
        "gflop": flop / 1e9, "gflops": flop / 1e9 / seconds,
        "peak_rss_bytes": peak_rss_bytes(), "threads": threads(),
    }))
}

fn gemm(n: usize, runs: usize, device: &Device) -> Result<serde_json::Value> {
    let a = Tensor::from_vec(synthetic(n, 1, 3), (n, n), device)?;
    let b = Tensor::from_vec(synthetic(n, 1, 4), (n, n), device)?;
    let (seconds, cpu, all) = time(runs, || {
        a.matmul(&b)?.sum_all()?.to_scalar::<f32>()?;
        Ok(())
    })?;
    let flop = 2.0 * (n as f64).powi(3);
    Ok(serde_json::json!({
        "what": "gemm", "size": n, "device": format!("{device:?}"),
        "seconds": seconds, "cpu_seconds": cpu, "runs_seconds": all, "gflops": flop / 1e9 / seconds,
        "peak_rss_bytes": peak_rss_bytes(), "threads": threads(),
    }))
}
