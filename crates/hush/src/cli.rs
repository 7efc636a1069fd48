use std::path::PathBuf;

use clap::{Args, Parser, Subcommand};

use hush_dataset::AuxSource;
use hush_pipeline::{EvalPlan, TrainOptions, ViewOverrides};
use hush_scene::procedural::{GeneratorOptions, Ingredients};

pub use crate::bench_cmd::BenchArgs;
pub use crate::dataset_cmd::DatasetArgs;
pub use crate::scene_cmd::SceneArgs;

#[derive(Parser, Debug)]
#[command(
    name = "hush",
    version,
    about = "Monte-Carlo denoising for your own renderer: render, dataset, train, denoise, eval"
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

// Parsed once per process: the size of the largest variant does not matter.
#[allow(clippy::large_enum_variant)]
#[derive(Subcommand, Debug)]
pub enum Command {
    /// Render a scene to a multi-layer EXR (beauty, albedo, diffuse, specular, normal, and the variance of each
    /// beauty pixel: its samples' variance / spp, computed stably).
    Render(RenderArgs),
    /// Render a dataset: several views of scenes, noisy images along an spp ladder, clean
    /// auxiliary features and references.
    Dataset(DatasetArgs),
    /// Generate procedural scenes.
    Scene(SceneArgs),
    /// Train a denoising U-Net on a dataset's training split.
    Train(TrainOptions),
    /// Denoise one image with a trained model.
    Denoise(DenoiseArgs),
    /// Write a trained U-Net as OIDN's Tensor Archive (.tza), which OIDN's own runtime runs.
    Export(crate::export_cmd::ExportArgs),
    /// Interpolate in weight space between a network and one fine-tuned from it (WiSE-FT).
    Blend(crate::blend_cmd::BlendArgs),
    /// Evaluate models and baselines against the noisy input on a dataset's test split: metrics, error
    /// against run time, pictures and a report.
    Eval(EvalArgs),
    /// Measurements behind `cargo xtask bench net` (JSON on stdout).
    #[command(hide = true)]
    Bench(BenchArgs),
    /// The reports of `cargo xtask sweep` from the plan it writes.
    #[command(hide = true)]
    SweepReport(crate::report_cmd::SweepReportArgs),
}

/// Camera and image overrides of `render`.
#[derive(Args, Debug, Clone, Default)]
pub struct ViewArgs {
    /// Image width in pixels (overrides the scene file).
    #[arg(long)]
    pub width: Option<u32>,
    /// Image height in pixels (overrides the scene file).
    #[arg(long)]
    pub height: Option<u32>,
    /// Vertical field of view in degrees (overrides the scene file).
    #[arg(long)]
    pub fov: Option<f32>,
    /// Camera position x,y,z.
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true)]
    pub origin: Option<[f32; 3]>,
    /// Point the camera looks at, x,y,z.
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true)]
    pub target: Option<[f32; 3]>,
    /// Camera up vector x,y,z.
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true)]
    pub up: Option<[f32; 3]>,
    /// Mitsuba's max_depth: 1 = emitters only, 2 = direct light, 8 = up to 7 bounces.
    #[arg(long)]
    pub max_depth: Option<u32>,
}

impl ViewArgs {
    pub fn overrides(&self) -> ViewOverrides {
        ViewOverrides {
            width: self.width,
            height: self.height,
            fov: self.fov,
            origin: self.origin,
            target: self.target,
            up: self.up,
            max_depth: self.max_depth,
        }
    }
}

/// Generator options shared by `scene generate` and `dataset --procedural`.
#[derive(Args, Debug, Clone)]
pub struct GeneratorArgs {
    /// What the generator may use: `default` (what the path tracer renders today), `all` (adds rough glass,
    /// rough plastic, textures and environment lights), or a list of roughdielectric, roughplastic, textures,
    /// environment.
    #[arg(long, default_value = "default", value_parser = Ingredients::parse)]
    pub ingredients: Ingredients,
    /// Place small OBJ meshes found below DIR/*/models/ (e.g. ../shared/scenes) as furniture, by path.
    #[arg(long, value_name = "DIR")]
    pub borrow_meshes: Option<PathBuf>,
}

impl GeneratorArgs {
    pub fn options(&self, width: u32, height: u32) -> GeneratorOptions {
        GeneratorOptions::rooms(self.ingredients, width, height, self.borrow_meshes.clone())
    }
}

#[derive(Args, Debug)]
pub struct RenderArgs {
    /// Scene file (Mitsuba XML).
    pub scene: PathBuf,
    /// Samples per pixel; with --time-limit, the most to render.
    #[arg(long, required_unless_present = "time_limit")]
    pub spp: Option<u32>,
    /// Render passes until this many seconds of tracing are spent (at least one pass; the
    /// last may run past the limit), for equal-time comparisons; prints and records the spp
    /// reached. With --spp, whichever is reached first ends the render.
    #[arg(long, value_name = "SECONDS")]
    pub time_limit: Option<f64>,
    /// Output EXR.
    #[arg(long)]
    pub out: PathBuf,
    #[command(flatten)]
    pub view: ViewArgs,
    /// Random seed: the same seed gives the same image.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Where each pixel's samples lie: independent (as Mitsuba's `independent` sampler; what hush's shipped
    /// models were trained on) or stratified (a scrambled (0, 2)-sequence per pixel: less noise on edges)
    #[arg(long, default_value = "independent", value_parser = parse_pixel_sampler)]
    pub pixel_sampler: hush_trace::PixelSampler,
    /// Also write an 8-bit sRGB preview of the beauty image.
    #[arg(long)]
    pub png: Option<PathBuf>,
    /// Write timing statistics (paths, wall and CPU seconds, adapter) as JSON.
    #[arg(long)]
    pub stats: Option<PathBuf>,
    /// Render with the generic kernel instead of one specialized to the scene (same image;
    /// for speed comparisons).
    #[arg(long)]
    pub generic: bool,
    /// Render 1 spp first, untimed, with the same kernel, so that the timed render (and its
    /// --stats) excludes compiling the kernel, as a peer renderer's second render in one process
    /// does; for speed comparisons. The warm-up's CPU-seconds are recorded beside.
    #[arg(long)]
    pub warm_up: bool,
}

#[derive(Args, Debug)]
pub struct DenoiseArgs {
    /// Trained model (.safetensors written by `hush train`, or OIDN's .tza weights) [default: built in, for the
    /// features given: hush's shipped hush_alb_nrm with albedo and normal (data/models/, its card beside it),
    /// else OIDN 2.5.1's official rt_hdr_alb with albedo, rt_hdr for color only].
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Noisy image: an RGB EXR, a multi-layer EXR from `hush render` whose layers then
    /// supply the auxiliary inputs, or an RGB PFM (OIDN's format; the features then come from the flags,
    /// in EXR or PFM).
    #[arg(long)]
    pub color: PathBuf,
    #[arg(long)]
    pub albedo: Option<PathBuf>,
    #[arg(long)]
    pub normal: Option<PathBuf>,
    #[arg(long)]
    pub diffuse: Option<PathBuf>,
    #[arg(long)]
    pub specular: Option<PathBuf>,
    /// The color's per-pixel variance (for models trained with the `variance` feature; a `hush render` EXR
    /// carries it as its `variance` layer).
    #[arg(long)]
    pub variance: Option<PathBuf>,
    /// Output EXR (R,G,B), or PFM where the name ends in `.pfm`.
    #[arg(long)]
    pub out: PathBuf,
    /// Where the network runs: cpu or cuda [default: cuda when hush is built with it, else cpu].
    #[arg(long)]
    pub device: Option<String>,
    /// Keep the input's value where every sample of the pixel agreed (variance 0 and a positive color over the
    /// pixel and its 8 neighbours: a constant sky or an emitter seen directly), with the color's variance from
    /// --variance or the `variance` layer of a `hush render` EXR; false: the network's output as OIDN's
    /// runtime gives it.
    #[arg(long, default_value_t = true, action = clap::ArgAction::Set)]
    pub keep_exact: bool,
    /// Before --keep-exact, mix the input back in by each pixel's standard error from the color's variance
    /// (as for --keep-exact), taking the network's relative error to be this (0.01 was chosen on validation
    /// scenes): the input's weight is tau²L²/(tau²L² + s²), L the denoised pixel's level and s² the variance
    /// of its mean over its 5×5 window. Off when not given.
    #[arg(long, value_parser = parse_relative_error)]
    pub blend_input: Option<f32>,
    /// Denoise in this many poses of the square's symmetries and average them: 1 the network as it is, 2 also
    /// flipped left to right, 4 the flips in x, y and both, 8 those and their transposes (8 times the time)
    /// [default: the shipped model's setting when --model is not given (8 for hush_alb_nrm, under which its
    /// card's guards hold), else 1].
    #[arg(long, value_parser = clap::value_parser!(u8).range(1..=8))]
    pub poses: Option<u8>,
    /// With several poses, put back the input's low band (a Gaussian of this std in pixels; 2 was chosen on
    /// validation scenes) where the outputs disagree, weighted by their spread against the band's noise from
    /// the render's variance (as for --keep-exact); `off` for none [default: the shipped model's setting when
    /// --model is not given (2 for hush_alb_nrm), else off].
    #[arg(long, value_parser = parse_sigma)]
    pub restore_low_band: Option<Sigma>,
}

#[derive(Args, Debug)]
pub struct EvalArgs {
    /// Dataset folder (from `hush dataset`); its test split is evaluated.
    #[arg(long)]
    pub dataset: PathBuf,
    /// Trained models to evaluate (.safetensors, or OIDN's .tza weights); repeatable. `A+B+C` evaluates the
    /// mean of those models' outputs as one method (an ensemble).
    #[arg(long = "model")]
    pub models: Vec<PathBuf>,
    /// Baselines to evaluate by name; repeatable or comma-separated. `noisy` (raw path tracing) is always
    /// evaluated; `all` asks for every known baseline; an unknown name is an error listing the known ones.
    #[arg(long = "baseline", value_delimiter = ',')]
    pub baselines: Vec<String>,
    /// Noisy inputs at these spp (all stored ones if not given).
    #[arg(long, value_delimiter = ',')]
    pub spp: Vec<u32>,
    /// Report folder: report.md, report.html, summary.json, error_vs_time.csv, plots, pictures and previews.
    #[arg(long)]
    pub out: PathBuf,
    /// Denoise timing: median of this many warm runs.
    #[arg(long, default_value_t = EvalPlan::DEFAULT_TIMING_RUNS)]
    pub timing_runs: usize,
    /// Auxiliary inputs of the denoisers: `noisy` (each noisy render's own, at its spp) or `clean` (the
    /// view's, rendered once at the dataset's --aux-spp).
    #[arg(long, default_value = "noisy", value_parser = parse_aux)]
    pub aux: AuxSource,
    /// Leave out OIDN's official weights (built in, run by hush), which are evaluated by default for each
    /// feature set among the models.
    #[arg(long)]
    pub no_official: bool,
    /// Evaluate every view of these scenes (either split) instead of the test split: the validation scenes
    /// of `hush train --validation`, to choose among models without looking at the test scenes.
    #[arg(long, value_delimiter = ',')]
    pub scenes: Vec<String>,
    /// Where the networks run: cpu or cuda [default: cuda when hush is built with it, else cpu].
    #[arg(long)]
    pub device: Option<String>,
    /// After each network (hush's models and OIDN's official weights alike), keep the noisy value of the
    /// pixels whose every sample agreed (variance 0 and a positive color over the pixel and its 8 neighbours:
    /// a constant sky or an emitter seen directly), where the dataset stores the render's variance; false:
    /// the networks' output as OIDN's runtime gives it.
    #[arg(long, default_value_t = true, action = clap::ArgAction::Set)]
    pub keep_exact: bool,
    /// After each network (before --keep-exact), mix the noisy input back in by each pixel's standard error
    /// from the render's variance, where the dataset stores it, taking the network's relative error to be this
    /// (0.01 was chosen on validation scenes): the input's weight is tau²L²/(tau²L² + s²), L the denoised
    /// pixel's level and s² the variance of its mean over its 5×5 window. Off when not given.
    #[arg(long, value_parser = parse_relative_error)]
    pub blend_input: Option<f32>,
    /// Denoise in this many poses of the square's symmetries and average them: 1 the network as it is, 2 also
    /// flipped left to right, 4 the flips in x, y and both, 8 those and their transposes (8 times the time).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u8).range(1..=8))]
    pub poses: u8,
    /// With several poses (or models), put back the input's low band (a Gaussian of this std in pixels; 2 was
    /// chosen on validation scenes) where the outputs disagree, weighted by their spread against the band's
    /// noise from the render's variance, where the dataset stores it. Off when not given (or `off`).
    #[arg(long, value_parser = parse_sigma)]
    pub restore_low_band: Option<Sigma>,
}

impl EvalArgs {
    pub fn plan(self) -> EvalPlan {
        EvalPlan {
            dataset: self.dataset,
            models: self.models,
            baselines: self.baselines,
            spp: self.spp,
            out: self.out,
            timing_runs: self.timing_runs,
            aux: self.aux,
            official: !self.no_official,
            scenes: self.scenes,
            device: self.device,
            keep_exact: self.keep_exact,
            blend_input: self.blend_input,
            poses: usize::from(self.poses),
            restore_low_band: self.restore_low_band.and_then(|s| s.0),
        }
    }
}

/// `--restore-low-band`: a Gaussian's std in pixels, or `None` for `off`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sigma(pub Option<f32>);

fn parse_sigma(s: &str) -> Result<Sigma, String> {
    if s == "off" {
        return Ok(Sigma(None));
    }
    match s.parse::<f32>() {
        Ok(v) if v.is_finite() && v > 0.0 && v <= 64.0 => Ok(Sigma(Some(v))),
        Ok(v) => Err(format!("a Gaussian's std in pixels above 0 and at most 64, got {v}")),
        Err(e) => Err(format!("{e}: a Gaussian's std in pixels, e.g. 2, or off")),
    }
}

fn parse_relative_error(s: &str) -> Result<f32, String> {
    match s.parse::<f32>() {
        Ok(v) if v.is_finite() && v > 0.0 => Ok(v),
        _ => Err(format!("'{s}': the network's relative error is a positive number, for example 0.01")),
    }
}

fn parse_aux(s: &str) -> Result<AuxSource, String> {
    AuxSource::parse(s).ok_or_else(|| format!("'{s}': use noisy or clean"))
}

fn parse_vec3(s: &str) -> Result<[f32; 3], String> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    let nums: Result<Vec<f32>, _> = parts.iter().map(|p| p.parse::<f32>()).collect();
    match nums {
        Ok(v) if v.len() == 3 && v.iter().all(|x| x.is_finite()) => Ok([v[0], v[1], v[2]]),
        _ => Err(format!("'{s}' is not three finite numbers x,y,z")),
    }
}

/// `--pixel-sampler`'s value.
pub fn parse_pixel_sampler(name: &str) -> Result<hush_trace::PixelSampler, String> {
    hush_trace::PixelSampler::parse(name)
}
