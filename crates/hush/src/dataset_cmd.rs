//! `hush dataset`: scenes → perspectives → noisy images along an spp ladder, clean features and
//! supersampled, firefly-filtered references, resumable and shardable; `hush dataset check|merge`.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use clap::{Args, Subcommand};
use glam::{Quat, Vec3};
use hush_dataset::{
    AuxKind, AuxRecord, CameraRecord, DatasetConfig, FireflyRecord, Layout, Manifest, PendingView, ProbeRecord,
    ProceduralRecord, ProceduralScene, ReferenceCheck, ReferenceRecord, RenderRecord, SceneEntry, SkippedScene, Split,
    ViewGeneration, check_dataset, check_image, despeckle, link_or_copy, luminance, read_rgb, temp_files, temp_target,
    write_rgb,
};
use hush_hash::SplitMix64;
use hush_scene::{Camera, Scene};
use hush_trace::{RenderOutput, RenderSettings, Renderer};
use indicatif::{MultiProgress, ProgressBar, ProgressStyle};

use crate::cli::ViewOverrides;
use crate::render_cmd::{load_scene, open_gpu};
use crate::scene_cmd::{GeneratorArgs, generate_into, summary_json};

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
    #[arg(long, default_value_t = 4)]
    pub views: u32,
    /// With a single scene, or with --split-views: how many of each scene's views (the last ones) form the
    /// test split.
    #[arg(long, default_value_t = 1)]
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
    #[arg(long, value_delimiter = ',', default_value = "1,2,4,8,16,32,64,128,256")]
    pub spp: Vec<u32>,
    /// Samples per (sub)pixel of the reference (rendered with an independent seed).
    #[arg(long, default_value_t = 1024)]
    pub ref_spp: u32,
    /// The reference is rendered at this many times the width and height, then box-downsampled.
    #[arg(long, default_value_t = 2)]
    pub ref_supersample: u32,
    /// Firefly filter of the reference: a pixel brighter than this many times its brightest neighbour is
    /// clamped (before downsampling). 0 turns the filter off.
    #[arg(long, default_value_t = hush_dataset::DEFAULT_FIREFLY_FACTOR)]
    pub firefly_factor: f32,
    /// Measure each reference's relMSE against an independent render at this spp (0 = no check; it costs
    /// a render of that many paths per pixel).
    #[arg(long, default_value_t = 0)]
    pub ref_check_spp: u32,
    /// Samples per pixel of the clean auxiliary features (first hit only).
    #[arg(long, default_value_t = 64)]
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

/// A generated view is kept when at least this fraction of its probe pixels receives light.
pub(crate) const MIN_LIT_FRACTION: f64 = 0.5;
/// Candidate cameras tried per generated view before the best one is kept anyway.
const MAX_ATTEMPTS: u32 = 8;
/// The probe render: this many pixels along the longer side, at this spp.
pub(crate) const PROBE_SIZE: u32 = 32;
pub(crate) const PROBE_SPP: u32 = 4;

/// A seed for one render, derived from the dataset seed and what is rendered, so that every
/// image (and the reference in particular) is statistically independent of every other.
fn render_seed(seed: u64, scene: &str, view: u32, what: &str) -> u64 {
    let mut h = SplitMix64(seed);
    let mut acc = h.next_u64();
    for b in scene.bytes().chain([0xff]).chain(what.bytes()) {
        acc = SplitMix64(acc ^ b as u64).next_u64();
    }
    SplitMix64(acc ^ view as u64).next_u64()
}

/// A candidate camera: it orbits the scene camera's target by up to ±20° of yaw and ±8° of pitch, moves
/// 10 % closer or farther, shifts the target by up to 3 % of the scene's size and scales the field of view
/// by ±10 %.
fn jitter_camera(base: &Camera, scene: &Scene, seed: u64) -> Camera {
    let mut rng = SplitMix64(seed);
    let (forward, right, up) = base.basis();
    let yaw = Quat::from_axis_angle(up, rng.uniform(-20.0, 20.0).to_radians());
    let pitch = Quat::from_axis_angle(right, rng.uniform(-8.0, 8.0).to_radians());
    let (lo, hi) = scene.bounds();
    let size = if lo.is_finite() && hi.is_finite() { (hi - lo).length() } else { 1.0 };
    let shift = Vec3::new(rng.uniform(-1.0, 1.0), rng.uniform(-1.0, 1.0), rng.uniform(-1.0, 1.0)) * 0.03 * size;
    let target = base.target + shift;
    let dist = (base.origin - base.target).length() * rng.uniform(0.9, 1.1);
    let dir = (yaw * pitch * forward).normalize();
    Camera {
        origin: target - dir * dist,
        target,
        up: base.up,
        fov_y_deg: (base.fov_y_deg * rng.uniform(0.9, 1.1)).min(170.0),
    }
}

/// The name of a scene file: its stem, or its folder's name for `scene.*`, made into a valid dataset name.
fn scene_name(path: &Path) -> String {
    let stem = match path.file_stem().and_then(|s| s.to_str()) {
        Some("scene") | None => path.parent().and_then(|p| p.file_name()).and_then(|s| s.to_str()).unwrap_or("scene"),
        Some(s) => s,
    };
    let name: String = stem.chars().map(|c| if c.is_ascii_alphanumeric() || c == '-' { c } else { '-' }).collect();
    if name.is_empty() { "scene".into() } else { name }
}

/// Scene files named on the command line, with folders expanded (sorted, so every shard sees one order).
fn collect_scene_files(inputs: &[PathBuf]) -> Result<Vec<PathBuf>> {
    fn walk(dir: &Path, out: &mut Vec<PathBuf>) -> Result<()> {
        let scene_xml = dir.join("scene.xml");
        if scene_xml.is_file() {
            out.push(scene_xml);
            return Ok(());
        }
        let mut entries: Vec<PathBuf> = std::fs::read_dir(dir)
            .with_context(|| format!("{}: cannot list the scene folder", dir.display()))?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .collect();
        entries.sort();
        for path in entries {
            if path.is_dir() {
                walk(&path, out)?;
            } else if matches!(
                path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase).as_deref(),
                Some("gltf" | "glb" | "obj")
            ) {
                out.push(path);
            }
        }
        Ok(())
    }
    let mut files = Vec::new();
    for input in inputs {
        if input.is_dir() {
            let before = files.len();
            walk(input, &mut files)?;
            if files.len() == before {
                bail!("{}: no scene.xml, .gltf, .glb or .obj file below this folder", input.display());
            }
        } else {
            files.push(input.clone());
        }
    }
    Ok(files)
}

/// A loaded scene of the job.
struct JobScene {
    name: String,
    path: PathBuf,
    scene: Scene,
    split: Option<Split>,
}

/// Loads every scene (those named and the generated ones); failures are reported and recorded as skipped
/// unless none loads.
fn load_scenes(args: &DatasetArgs, generated: &[PathBuf]) -> Result<(Vec<JobScene>, Vec<SkippedScene>)> {
    let overrides = ViewOverrides { width: args.size, height: args.size, ..Default::default() };
    let mut loaded: Vec<JobScene> = Vec::new();
    let mut skipped = Vec::new();
    let mut files = collect_scene_files(&args.scenes)?;
    files.extend(generated.iter().cloned());
    for path in files {
        match load_scene(&path, &overrides) {
            Ok(scene) => {
                let base = scene_name(&path);
                let mut name = base.clone();
                let mut k = 2;
                while loaded.iter().any(|s| s.name == name) {
                    name = format!("{base}-{k}");
                    k += 1;
                }
                loaded.push(JobScene { name, path, scene, split: None });
            }
            Err(e) => {
                eprintln!("skipped {}: {e:#}", path.display());
                skipped.push(SkippedScene { path: path.display().to_string(), reason: format!("{e:#}") });
            }
        }
    }
    if loaded.is_empty() {
        let reasons: Vec<String> = skipped.iter().map(|s| format!("  {}: {}", s.path, s.reason)).collect();
        bail!("no scene could be loaded:\n{}", reasons.join("\n"));
    }
    loaded.sort_by(|a, b| a.name.cmp(&b.name));
    for name in &args.test_scenes {
        if !loaded.iter().any(|s| &s.name == name) {
            let names: Vec<&str> = loaded.iter().map(|s| s.name.as_str()).collect();
            bail!("--test-scenes names {name:?}, which is not a loaded scene; the scenes are {names:?}");
        }
    }
    let n = loaded.len();
    if !args.test_scenes.is_empty() {
        for s in &mut loaded {
            s.split = Some(if args.test_scenes.contains(&s.name) { Split::Test } else { Split::Train });
        }
    } else if n > 1 && !args.split_views {
        // The thesis's proportion, 5 test scenes in 13, spread evenly over the sorted names.
        let tests = ((n * 5 + 6) / 13).max(1);
        for (i, s) in loaded.iter_mut().enumerate() {
            let test = (i + 1) * tests / n > i * tests / n;
            s.split = Some(if test { Split::Test } else { Split::Train });
        }
    }
    Ok((loaded, skipped))
}

fn camera_record(camera: &Camera, scene: &Scene) -> CameraRecord {
    CameraRecord {
        origin: camera.origin.to_array(),
        target: camera.target.to_array(),
        up: camera.up.to_array(),
        fov_y_deg: camera.fov_y_deg,
        width: scene.film.width,
        height: scene.film.height,
    }
}

fn camera_of(r: &CameraRecord) -> Camera {
    Camera { origin: r.origin.into(), target: r.target.into(), up: r.up.into(), fov_y_deg: r.fov_y_deg }
}

/// What every view needs while it renders.
struct Ctx<'a> {
    args: &'a DatasetArgs,
    layout: Layout,
    renderer: Renderer<'a>,
    bars: MultiProgress,
    total: ProgressBar,
    own: Manifest,
    own_path: PathBuf,
    rendered: usize,
}

impl Ctx<'_> {
    /// Renders with a bar for this image below the bar of the whole job.
    fn render(&self, scene: &Scene, spp: u32, seed: u64, label: &str) -> Result<RenderOutput> {
        let bar = self.bars.add(ProgressBar::new(spp as u64));
        bar.set_style(
            ProgressStyle::with_template("{prefix} [{bar:30}] {pos}/{len} spp {msg} eta {eta}")
                .expect("valid template")
                .progress_chars("=> "),
        );
        bar.set_prefix(label.to_string());
        let pixels = scene.film.width as f64 * scene.film.height as f64;
        let start = std::time::Instant::now();
        let out = self.renderer.render(scene, &RenderSettings { spp, seed }, &mut |done, _| {
            let rate = pixels * done as f64 / start.elapsed().as_secs_f64().max(1e-9) / 1e6;
            bar.set_message(format!("{rate:.2} M paths/s"));
            bar.set_position(done as u64);
        });
        bar.finish_and_clear();
        self.bars.remove(&bar);
        let out = out?;
        if out.discarded_samples > 0 {
            self.note(format!("warning: {label}: {} non-finite path samples were discarded", out.discarded_samples));
        }
        Ok(out)
    }

    fn note(&self, line: String) {
        if self.bars.is_hidden() {
            eprintln!("{line}");
        } else {
            let _ = self.bars.println(line);
        }
    }

    /// Stores what is finished of a view in this run's manifest file at once, so a killed run keeps it.
    fn record(&mut self, progress: &PendingView) -> Result<()> {
        self.own.upsert_progress(progress.clone())?;
        self.own.save_file(&self.own_path)?;
        Ok(())
    }

    /// Whether `file` is a finished image of the camera's size (readable, finite).
    fn valid(&self, file: &str, camera: &CameraRecord) -> bool {
        check_image(&self.layout.path(file), camera.width as usize, camera.height as usize).is_ok()
    }
}

/// Picks the camera of a generated view: candidates are drawn from the view's seed until a cheap probe
/// render shows that at least half of the image receives light; after `MAX_ATTEMPTS` the best is kept.
fn generate_view(ctx: &Ctx, job: &JobScene, v: u32) -> Result<(Camera, ViewGeneration)> {
    let seed = render_seed(ctx.args.seed, &job.name, v, "camera");
    let film = job.scene.film;
    let scale = PROBE_SIZE as f32 / film.width.max(film.height) as f32;
    let (pw, ph) = if scale < 1.0 {
        (((film.width as f32 * scale).round() as u32).max(1), ((film.height as f32 * scale).round() as u32).max(1))
    } else {
        (film.width, film.height)
    };
    let mut best: Option<(f64, Camera, u32)> = None;
    for attempt in 0..MAX_ATTEMPTS {
        let camera = jitter_camera(&job.scene.camera, &job.scene, seed.wrapping_add(attempt as u64));
        if camera.validate().is_err() {
            continue;
        }
        let mut probe = job.scene.clone();
        probe.camera = camera;
        probe.film.width = pw;
        probe.film.height = ph;
        let out = ctx.render(&probe, PROBE_SPP, seed ^ 0x0050_524f_4245 ^ attempt as u64, "probe")?;
        let lit = out.color.data.chunks_exact(3).filter(|p| luminance(p) > 0.0).count();
        let fraction = lit as f64 / (pw as f64 * ph as f64);
        if best.as_ref().is_none_or(|b| fraction > b.0) {
            best = Some((fraction, camera, attempt));
        }
        if fraction >= MIN_LIT_FRACTION {
            break;
        }
    }
    let (fraction, camera, attempt) =
        best.with_context(|| format!("{}: no valid camera among {MAX_ATTEMPTS} candidates", job.path.display()))?;
    let accepted = fraction >= MIN_LIT_FRACTION;
    if !accepted {
        ctx.note(format!(
            "warning: {} v{v:03}: no candidate view had {:.0} % of its pixels lit; keeping the best ({:.0} %)",
            job.name,
            MIN_LIT_FRACTION * 100.0,
            fraction * 100.0
        ));
    }
    let probe = ProbeRecord { width: pw, height: ph, spp: PROBE_SPP, lit_fraction: fraction, accepted };
    Ok((camera, ViewGeneration { kind: "generated".into(), seed, attempt, probe: Some(probe) }))
}

/// Renders (or keeps) every image of one view.
fn render_view(ctx: &mut Ctx, known: &Manifest, job: &JobScene, v: u32, split: Split) -> Result<()> {
    let args = ctx.args;
    let name = job.name.as_str();
    let view = format!("v{v:03}");
    let label = format!("{name} {view}");
    let size = (job.scene.film.width, job.scene.film.height);
    let previous = known
        .progress(name, &view)
        .filter(|p| (p.camera.width, p.camera.height) == size && p.camera.fov_y_deg.is_finite());

    // The camera: the scene's own, a recorded one with the same seed, or a newly generated one.
    let (camera, generation) = if v == 0 {
        (job.scene.camera, ViewGeneration { kind: "scene".into(), seed: 0, attempt: 0, probe: None })
    } else {
        let seed = render_seed(args.seed, name, v, "camera");
        match previous.as_ref().filter(|p| p.generation.kind == "generated" && p.generation.seed == seed) {
            Some(p) => (camera_of(&p.camera), p.generation.clone()),
            None => generate_view(ctx, job, v)?,
        }
    };
    let mut scene = job.scene.clone();
    scene.camera = camera;
    let camera = camera_record(&camera, &scene);
    let previous = previous.filter(|p| p.camera == camera);
    let mut progress = PendingView {
        scene: name.to_string(),
        view: view.clone(),
        split,
        camera: camera.clone(),
        generation,
        noisy: Vec::new(),
        reference: None,
        aux: None,
    };

    let mut spps = args.spp.clone();
    spps.sort_unstable();
    spps.dedup();
    for &spp in &spps {
        let seed = render_seed(args.seed, name, v, &format!("noisy-{spp}"));
        let file = Layout::noisy_name(name, &view, spp);
        let kept = previous.as_ref().and_then(|p| p.noisy.iter().find(|r| r.spp == spp && r.seed == seed)).cloned();
        match kept.filter(|r| r.file == file && ctx.valid(&file, &camera)) {
            Some(r) => progress.noisy.push(r),
            None => {
                let out = ctx.render(&scene, spp, seed, &format!("{label} {spp} spp"))?;
                write_rgb(ctx.layout.path(&file), &out.color)?;
                progress.noisy.push(RenderRecord { spp, seed, file, render_seconds: out.seconds });
                ctx.rendered += 1;
                ctx.record(&progress)?;
            }
        }
        ctx.total.inc(1);
    }

    let aux_files: Vec<String> = AuxKind::ALL.iter().map(|&k| Layout::aux_name(name, &view, k)).collect();
    let aux_seed = render_seed(args.seed, name, v, "aux");
    let kept = previous
        .as_ref()
        .and_then(|p| p.aux.clone())
        .filter(|a| a.spp == args.aux_spp && a.seed == aux_seed && aux_files.iter().all(|f| ctx.valid(f, &camera)));
    let aux = match kept {
        Some(a) => a,
        None => {
            // Features come from the first hit only, so a depth-1 render gives them at a
            // fraction of a full path's cost.
            let mut first_hit = scene.clone();
            first_hit.max_depth = 1;
            let out = ctx.render(&first_hit, args.aux_spp, aux_seed, &format!("{label} features"))?;
            for (kind, file) in AuxKind::ALL.iter().zip(&aux_files) {
                let image = match kind {
                    AuxKind::Albedo => &out.albedo,
                    AuxKind::Normal => &out.normal,
                    AuxKind::Diffuse => &out.diffuse,
                    AuxKind::Specular => &out.specular,
                };
                write_rgb(ctx.layout.path(file), image)?;
            }
            ctx.rendered += 1;
            AuxRecord {
                spp: args.aux_spp,
                seed: aux_seed,
                render_seconds: out.seconds,
                albedo: aux_files[0].clone(),
                normal: aux_files[1].clone(),
                diffuse: aux_files[2].clone(),
                specular: aux_files[3].clone(),
            }
        }
    };
    // OIDN's toolkit reads `<scene>_<view>_<spp>.alb.exr` / `.nrm.exr` beside every noisy render.
    for &spp in &spps {
        for kind in AuxKind::OIDN {
            let src = ctx.layout.path(aux.file(kind));
            link_or_copy(&src, &ctx.layout.path(&Layout::noisy_aux_name(name, &view, spp, kind)))?;
        }
    }
    progress.aux = Some(aux);
    ctx.record(&progress)?;
    ctx.total.inc(1);

    let ref_file = Layout::reference_name(name, &view);
    let ref_seed = render_seed(args.seed, name, v, "reference");
    let kept = previous.as_ref().and_then(|p| p.reference.clone()).filter(|r| {
        r.spp == args.ref_spp
            && r.seed == ref_seed
            && r.supersample == args.ref_supersample
            && r.firefly.factor == args.firefly_factor
            && r.file == ref_file
            && ctx.valid(&ref_file, &camera)
    });
    let (mut reference, mut reference_image) = match kept {
        Some(r) => (r, None),
        None => {
            let ss = args.ref_supersample;
            let mut big = scene.clone();
            big.film.width *= ss;
            big.film.height *= ss;
            let out = ctx.render(&big, args.ref_spp, ref_seed, &format!("{label} reference {ss}x{ss}"))?;
            let mut color = out.color;
            let stats = if args.firefly_factor > 0.0 {
                despeckle(&mut color, args.firefly_factor)?
            } else {
                hush_dataset::DespeckleStats { clamped_pixels: 0, energy_removed: 0.0 }
            };
            let image = color.downsample_box(ss as usize)?;
            write_rgb(ctx.layout.path(&ref_file), &image)?;
            ctx.rendered += 1;
            let record = ReferenceRecord {
                spp: args.ref_spp,
                seed: ref_seed,
                file: ref_file.clone(),
                render_seconds: out.seconds,
                supersample: ss,
                firefly: FireflyRecord {
                    factor: args.firefly_factor,
                    clamped_pixels: stats.clamped_pixels,
                    energy_removed: stats.energy_removed,
                },
                check: None,
            };
            (record, Some(image))
        }
    };
    progress.reference = Some(reference.clone());
    if args.ref_check_spp > 0 {
        ctx.record(&progress)?;
    }
    ctx.total.inc(1);

    if args.ref_check_spp > 0 {
        let seed = render_seed(args.seed, name, v, "reference-check");
        if reference.check.as_ref().is_none_or(|c| c.spp != args.ref_check_spp || c.seed != seed) {
            let out = ctx.render(&scene, args.ref_check_spp, seed, &format!("{label} reference check"))?;
            let image = match reference_image.take() {
                Some(i) => i,
                None => read_rgb(ctx.layout.path(&ref_file))?,
            };
            let rel_mse = hush_eval::rel_mse(&image, &out.color)?;
            reference.check =
                Some(ReferenceCheck { spp: args.ref_check_spp, seed, render_seconds: out.seconds, rel_mse });
            ctx.rendered += 1;
        }
        ctx.total.inc(1);
    }
    let check = reference.check.as_ref().map(|c| format!(", reference relMSE {:.2e}", c.rel_mse)).unwrap_or_default();
    progress.reference = Some(reference);
    ctx.record(&progress)?;
    ctx.note(format!("{label}: done ({split:?}{check})"));
    Ok(())
}

fn images_per_view(args: &DatasetArgs) -> u64 {
    let mut spps = args.spp.clone();
    spps.sort_unstable();
    spps.dedup();
    spps.len() as u64 + 2 + u64::from(args.ref_check_spp > 0)
}

pub fn run(args: DatasetArgs) -> Result<()> {
    match &args.action {
        Some(DatasetAction::Check { dir }) => return check(dir),
        Some(DatasetAction::Merge { dir }) => return merge(dir),
        None => {}
    }
    let out = args.out.clone().context("--out is required")?;
    if args.spp.is_empty() || args.spp.contains(&0) || args.ref_spp == 0 || args.aux_spp == 0 {
        bail!("every spp (--spp, --ref-spp, --aux-spp) must be at least 1");
    }
    if args.views == 0 || args.test_views > args.views {
        bail!("--views must be at least 1 and --test-views at most --views");
    }
    if args.ref_supersample == 0 || !(args.firefly_factor == 0.0 || args.firefly_factor >= 1.0) {
        bail!("--ref-supersample must be at least 1 and --firefly-factor 0 (off) or at least 1");
    }
    std::fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;
    let layout = Layout::new(&out);
    let gpu = open_gpu()?;
    let renderer = Renderer::new(&gpu)?;
    let procedural = if args.procedural > 0 { Some(generate_procedural(&args, &out, &renderer)?) } else { None };
    let generated: Vec<PathBuf> = procedural.iter().flat_map(|p| p.scenes.iter().map(|s| out.join(&s.path))).collect();
    let (scenes, skipped) = load_scenes(&args, &generated)?;

    // The jobs, one per (scene, view), dealt round-robin to the shards.
    let (shard, shards) = args.shard.unwrap_or((0, 1));
    let jobs: Vec<(usize, u32)> = scenes
        .iter()
        .enumerate()
        .flat_map(|(s, _)| (0..args.views).map(move |v| (s, v)))
        .enumerate()
        .filter(|(j, _)| *j as u32 % shards == shard)
        .map(|(_, job)| job)
        .collect();

    let config = DatasetConfig {
        seed: args.seed,
        views: args.views,
        spp: {
            let mut s = args.spp.clone();
            s.sort_unstable();
            s.dedup();
            s
        },
        aux_spp: args.aux_spp,
        ref_spp: args.ref_spp,
        ref_supersample: args.ref_supersample,
        firefly_factor: args.firefly_factor,
        ref_check_spp: args.ref_check_spp,
        size: args.size,
        scenes: scenes
            .iter()
            .map(|s| SceneEntry {
                name: s.name.clone(),
                path: s.path.display().to_string(),
                split: s.split,
                triangles: s.scene.triangle_count(),
            })
            .collect(),
        skipped,
        procedural,
    };
    let known = Manifest::load_or_default(&out)?;
    let (mut own, own_path) = match args.shard {
        None => (known.clone(), layout.manifest_path()),
        Some((i, n)) => {
            let path = layout.shard_manifest_path(i, n);
            (if path.exists() { Manifest::load_file(&path)? } else { Manifest::default() }, path)
        }
    };
    own.config = Some(config);

    // Temporary files of writes a killed run of these jobs left behind.
    let own_name = own_path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    let prefixes: Vec<String> = jobs.iter().map(|&(s, v)| format!("{}_v{v:03}_", scenes[s].name)).collect();
    for tmp in temp_files(&out)? {
        let file = tmp.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        if let Some(target) = temp_target(&file)
            && (target == own_name || prefixes.iter().any(|p| target.starts_with(p.as_str())))
        {
            std::fs::remove_file(&tmp).with_context(|| format!("removing {}", tmp.display()))?;
        }
    }

    let bars = MultiProgress::new();
    let total = bars.add(ProgressBar::new(jobs.len() as u64 * images_per_view(&args)));
    total.set_style(
        ProgressStyle::with_template("dataset [{bar:30}] {pos}/{len} images, {msg} elapsed {elapsed} eta {eta}")
            .expect("valid template")
            .progress_chars("=> "),
    );
    let mut ctx = Ctx { args: &args, layout, renderer, bars, total, own, own_path, rendered: 0 };
    let start = std::time::Instant::now();
    let n_views = args.views;
    for (k, &(s, v)) in jobs.iter().enumerate() {
        let job = &scenes[s];
        ctx.total.set_message(format!("view {}/{}", k + 1, jobs.len()));
        let split = job.split.unwrap_or(if v >= n_views - args.test_views { Split::Test } else { Split::Train });
        render_view(&mut ctx, &known, job, v, split)
            .with_context(|| format!("{} v{v:03} (scene {})", job.name, job.path.display()))?;
    }
    // Finish: make sure the manifest carries this run's settings even when nothing needed rendering.
    ctx.own.save_file(&ctx.own_path)?;
    ctx.total.finish_and_clear();
    eprintln!(
        "dataset: {} views of shard {shard}/{shards} ({} images rendered, the rest kept) in {:.1} s → {}",
        jobs.len(),
        ctx.rendered,
        start.elapsed().as_secs_f64(),
        ctx.own_path.display()
    );
    if args.shard.is_some() {
        eprintln!(
            "dataset: readers merge the shard manifests; `hush dataset merge {}` writes manifest.json",
            out.display()
        );
    }
    Ok(())
}

/// The procedural scenes of a run: scene `i` lives in `scenes/proc_<seed>_<i>/scene.xml` beside its assets and
/// a `scene.json` that says how it was generated; a scene whose `scene.json` matches the run's settings is kept,
/// any other is generated (and probed) again.
fn generate_procedural(args: &DatasetArgs, out: &Path, renderer: &Renderer) -> Result<ProceduralRecord> {
    let size = args.size.unwrap_or(256);
    let options = args.generator.options(size, size);
    let mut scenes = Vec::new();
    let (mut kept, start) = (0, std::time::Instant::now());
    for index in 0..args.procedural as u64 {
        let rel = format!("scenes/proc_{}_{index}/scene.xml", args.seed);
        let xml = out.join(&rel);
        let json = xml.with_file_name("scene.json");
        let want = serde_json::json!({
            "generator_version": hush_scene::procedural::GENERATOR_VERSION,
            "seed": args.seed,
            "index": index,
            "features": options.ingredients.describe(),
            "width": size,
            "height": size,
            "borrow_meshes": options.borrow_meshes,
        });
        let previous = std::fs::read_to_string(&json)
            .ok()
            .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
            .filter(|p| xml.is_file() && want.as_object().is_some_and(|w| w.iter().all(|(k, v)| &p[k] == v)));
        let summary = match previous {
            Some(p) => {
                kept += 1;
                p
            }
            None => {
                let written = generate_into(&xml, args.seed, index, &options, Some(renderer))?;
                let mut s = summary_json(&written, args.seed, index, &options);
                if let (Some(s), Some(w)) = (s.as_object_mut(), want.as_object()) {
                    s.extend(w.clone());
                }
                hush_dataset::write_atomic(&json, |tmp| std::fs::write(tmp, serde_json::to_string_pretty(&s)?))
                    .with_context(|| format!("writing {}", json.display()))?;
                s
            }
        };
        scenes.push(ProceduralScene {
            index,
            path: rel,
            scene_seed: summary["scene_seed"].as_u64().context("scene.json without scene_seed")?,
            attempt: summary["attempt"].as_u64().unwrap_or(0) as u32,
            style: summary["style"].as_str().unwrap_or_default().to_string(),
            probe_lit_fraction: summary["probe_lit_fraction"].as_f64(),
        });
    }
    eprintln!(
        "procedural: {} scenes ({} generated, {kept} kept) in {:.1} s → {}",
        args.procedural,
        args.procedural as usize - kept,
        start.elapsed().as_secs_f64(),
        out.join("scenes").display()
    );
    Ok(ProceduralRecord {
        count: args.procedural,
        seed: args.seed,
        generator_version: hush_scene::procedural::GENERATOR_VERSION,
        features: options.ingredients.describe(),
        scenes,
    })
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
