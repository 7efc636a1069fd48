//! `hush dataset`: render a dataset (hush-pipeline's `dataset`) with progress bars; `hush dataset check|merge`.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use clap::{Args, Subcommand};
use hush_dataset::{Layout, Manifest, check_dataset};
use hush_pipeline::DatasetPlan;
use hush_trace::Renderer;

use crate::cli::GeneratorArgs;
use crate::progress::Bars;

#[derive(Args, Debug)]
#[command(args_conflicts_with_subcommands = true, subcommand_negates_reqs = true)]
pub struct DatasetArgs {
    #[command(subcommand)]
    pub action: Option<DatasetAction>,
    /// Scene files (Mitsuba XML, glTF, OBJ) or folders: a folder contributes every `scene.xml` below it
    /// (without looking further inside that scene's folder) and every `.gltf`, `.glb` and `.obj` elsewhere.
    /// Scenes that fail to load are reported as skipped.
    #[arg(required_unless_present = "procedural")]
    pub scenes: Vec<PathBuf>,
    /// Also generate this many procedural scenes (seeded by --seed) into OUT/scenes/proc_<seed>_<i>/ and render
    /// them like the others. Re-running keeps the scenes already generated with the same settings.
    #[arg(long, default_value_t = 0)]
    pub procedural: u32,
    #[command(flatten)]
    pub generator: GeneratorArgs,
    /// Output folder (created; re-running resumes and skips finished, valid images).
    #[arg(long, required = true)]
    pub out: Option<PathBuf>,
    /// Views per scene: v000 is the scene's own camera, the others are generated around it.
    #[arg(long, default_value_t = DatasetPlan::DEFAULT_VIEWS)]
    pub views: u32,
    /// With a single scene, or with --split-views: how many of each scene's views (the last ones) form the
    /// test split.
    #[arg(long, default_value_t = DatasetPlan::DEFAULT_TEST_VIEWS)]
    pub test_views: u32,
    /// With several scenes: hold out each scene's last --test-views views instead of whole scenes, so every
    /// scene is trained on and tested on other views of it.
    #[arg(long, conflicts_with = "test_scenes")]
    pub split_views: bool,
    /// Scenes (by name) whose views form the test split. Default with several scenes: 5 in 13 of them
    /// (as the thesis: 8 train, 5 test), evenly spread over the scenes sorted by name.
    #[arg(long, value_delimiter = ',')]
    pub test_scenes: Vec<String>,
    /// Noisy images per view, at these samples per pixel.
    #[arg(long, value_delimiter = ',', default_values_t = DatasetPlan::DEFAULT_SPP)]
    pub spp: Vec<u32>,
    /// Samples per (sub)pixel of the reference (rendered with an independent seed).
    #[arg(long, default_value_t = DatasetPlan::DEFAULT_REF_SPP)]
    pub ref_spp: u32,
    /// Samples per (sub)pixel of the test split's references (default: --ref-spp). Scoring a denoiser
    /// needs cleaner references than training on them does.
    #[arg(long)]
    pub test_ref_spp: Option<u32>,
    /// The reference is rendered at this many times the width and height, then box-downsampled (a film
    /// with a tent or Gaussian filter: at 1× with this factor² times the samples, which keeps its filter).
    #[arg(long, default_value_t = DatasetPlan::DEFAULT_REF_SUPERSAMPLE)]
    pub ref_supersample: u32,
    /// Firefly filter of the reference: a pixel brighter than this many times its brightest neighbour is
    /// clamped (before downsampling). 0 turns the filter off.
    #[arg(long, default_value_t = hush_dataset::DEFAULT_FIREFLY_FACTOR)]
    pub firefly_factor: f32,
    /// Measure each reference's relMSE against an independent render at this spp (0 = no check; it costs
    /// a render of that many paths per pixel).
    #[arg(long, default_value_t = 0)]
    pub ref_check_spp: u32,
    /// Where each pixel's samples lie: independent (what hush's shipped models were trained on) or
    /// stratified (a scrambled (0, 2)-sequence per pixel: less noise on edges). Recorded per image: a
    /// resume renders again what the other sampler rendered.
    #[arg(long, default_value = "independent", value_parser = crate::cli::parse_pixel_sampler)]
    pub pixel_sampler: hush_trace::PixelSampler,
    /// Render each test view's spp ladder this many times, each render with its own seed (1: once). `hush eval`
    /// then scores every case by the mean over its renders: one render decides a denoiser's PSNR by a few pixels
    /// where a light is smaller than a pixel. The repeats go under repeats/, out of OIDN's toolkit's way.
    #[arg(long, default_value_t = 1)]
    pub test_repeats: u32,
    /// Samples per pixel of the clean auxiliary features (first hit only).
    #[arg(long, default_value_t = DatasetPlan::DEFAULT_AUX_SPP)]
    pub aux_spp: u32,
    /// Square image size in pixels (overrides the scene files).
    #[arg(long)]
    pub size: Option<u32>,
    /// Seed of the generated views and of every render.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Render only shard i of n (i/n, 0-based): a deterministic share of the (scene, view) jobs. Shards
    /// write their own manifest part into the shared folder; readers merge them.
    #[arg(long, value_parser = parse_shard)]
    pub shard: Option<(u32, u32)>,
}

#[derive(Subcommand, Debug)]
pub enum DatasetAction {
    /// Verify a dataset: completeness, sizes, NaN/Inf, manifest consistency. Exits non-zero on a problem.
    Check {
        /// Dataset folder.
        dir: PathBuf,
    },
    /// Merge the shard parts of a dataset into its manifest.json.
    Merge {
        /// Dataset folder.
        dir: PathBuf,
    },
}

fn parse_shard(s: &str) -> Result<(u32, u32), String> {
    let parsed = s.split_once('/').and_then(|(i, n)| Some((i.trim().parse().ok()?, n.trim().parse().ok()?)));
    match parsed {
        Some((i, n)) if n > 0 && i < n => Ok((i, n)),
        _ => Err(format!("'{s}' is not a shard i/n with 0 <= i < n (e.g. 0/4; Slurm: $SLURM_ARRAY_TASK_ID/4)")),
    }
}

impl DatasetArgs {
    fn plan(self, out: PathBuf) -> DatasetPlan {
        DatasetPlan {
            scenes: self.scenes,
            procedural: self.procedural,
            ingredients: self.generator.ingredients,
            borrow_meshes: self.generator.borrow_meshes,
            out,
            views: self.views,
            test_views: self.test_views,
            split_views: self.split_views,
            test_scenes: self.test_scenes,
            spp: self.spp,
            ref_spp: self.ref_spp,
            test_ref_spp: self.test_ref_spp,
            ref_supersample: self.ref_supersample,
            firefly_factor: self.firefly_factor,
            ref_check_spp: self.ref_check_spp,
            aux_spp: self.aux_spp,
            size: self.size,
            seed: self.seed,
            shard: self.shard,
            pixel_sampler: self.pixel_sampler,
            test_repeats: self.test_repeats,
        }
    }
}

pub fn run(args: DatasetArgs) -> Result<()> {
    match &args.action {
        Some(DatasetAction::Check { dir }) => return check(dir),
        Some(DatasetAction::Merge { dir }) => return merge(dir),
        None => {}
    }
    let out = args.out.clone().context("--out is required")?;
    let plan = args.plan(out);
    plan.validate()?;
    let gpu = crate::open_gpu()?;
    let renderer = Renderer::new(&gpu)?;
    let built = hush_pipeline::dataset::build(&plan, &renderer, &Bars::default())?;
    let (shard, shards) = plan.shard.unwrap_or((0, 1));
    eprintln!(
        "dataset: {} views of shard {shard}/{shards} ({} images rendered, the rest kept) in {:.1} s → {}",
        built.views,
        built.rendered,
        built.seconds,
        built.manifest.display()
    );
    if plan.shard.is_some() {
        eprintln!(
            "dataset: readers merge the shard manifests; `hush dataset merge {}` writes manifest.json",
            plan.out.display()
        );
    }
    Ok(())
}

fn check(dir: &Path) -> Result<()> {
    let report = check_dataset(dir)?;
    if report.ok() {
        eprintln!("{}: ok ({} views, {} image files checked)", dir.display(), report.views, report.files_checked);
        return Ok(());
    }
    for p in &report.problems {
        eprintln!("  {p}");
    }
    bail!(
        "{}: {} problem(s) (listed above) in {} views, {} image files checked",
        dir.display(),
        report.problems.len(),
        report.views,
        report.files_checked
    )
}

fn merge(dir: &Path) -> Result<()> {
    let parts = hush_dataset::manifest_files(dir)?;
    let manifest = Manifest::load(dir)?;
    manifest.save(dir)?;
    eprintln!(
        "{}: merged {} manifest file(s): {} finished views, {} pending",
        Layout::new(dir).manifest_path().display(),
        parts.len(),
        manifest.views.len(),
        manifest.pending.len()
    );
    Ok(())
}
