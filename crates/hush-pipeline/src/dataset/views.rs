//! One view of a dataset: its camera (the scene's own, or a generated one that the probe accepts), the noisy
//! images along the spp ladder, the clean features and the reference, each kept when a previous run left it
//! finished and valid.

use std::path::PathBuf;

use anyhow::{Context, Result};
use glam::{Quat, Vec3};
use hush_dataset::{
    AuxFiles, AuxKind, AuxRecord, CameraRecord, FireflyRecord, Layout, Manifest, PendingView, ProbeRecord,
    ReferenceCheck, ReferenceRecord, RenderRecord, Split, ViewGeneration, check_image, despeckle, read_rgb, write_rgb,
};
use hush_hash::SplitMix64;
use hush_scene::{Camera, PixelFilter, Scene};
use hush_trace::{RenderOutput, RenderSettings, Renderer};

use super::scenes::JobScene;
use super::{DatasetPlan, sampler_record};
use crate::Observer;
use crate::probe::{MAX_ATTEMPTS, MIN_LIT_FRACTION, PROBE_SEED, PROBE_SPP, lit_fraction, probe_size};

/// A seed for one render, derived from the dataset seed and what is rendered, so that every
/// image (and the reference in particular) is statistically independent of every other.
pub fn render_seed(seed: u64, scene: &str, view: u32, what: &str) -> u64 {
    let mut h = SplitMix64(seed);
    let mut acc = h.next_u64();
    for b in scene.bytes().chain([0xff]).chain(what.bytes()) {
        acc = SplitMix64(acc ^ b as u64).next_u64();
    }
    SplitMix64(acc ^ view as u64).next_u64()
}

/// How a reference is rendered: samples per subpixel and the supersampling factor. Box-downsampling
/// an `ss`× render is the same box filter at 1×, but not the same tent or Gaussian: those would keep
/// their radius in subpixels and end narrower than the noisy images' filter (a sharper reference that
/// no number of samples brings a noisy render to). A film with such a filter gets its reference at
/// 1× with the same paths per pixel, `spp × ss²`.
pub fn reference_sampling(spp: u32, ss: u32, filter: PixelFilter) -> (u32, u32) {
    match filter {
        PixelFilter::Box => (spp, ss),
        PixelFilter::Tent { .. } | PixelFilter::Gaussian { .. } => (spp.saturating_mul(ss * ss), 1),
    }
}

/// A candidate camera: it orbits the scene camera's target by up to ±20° of yaw and ±8° of pitch, moves
/// 10 % closer or farther, shifts the target by up to 3 % of the scene's size and scales the field of view
/// by ±10 %.
pub fn jitter_camera(base: &Camera, scene: &Scene, seed: u64) -> Camera {
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

pub(crate) fn camera_record(camera: &Camera, scene: &Scene) -> CameraRecord {
    CameraRecord {
        origin: camera.origin.to_array(),
        target: camera.target.to_array(),
        up: camera.up.to_array(),
        fov_y_deg: camera.fov_y_deg,
        width: scene.film.width,
        height: scene.film.height,
    }
}

pub(crate) fn camera_of(r: &CameraRecord) -> Camera {
    Camera { origin: r.origin.into(), target: r.target.into(), up: r.up.into(), fov_y_deg: r.fov_y_deg }
}

/// What every view needs while it renders.
pub(crate) struct Ctx<'a> {
    pub(crate) plan: &'a DatasetPlan,
    pub(crate) layout: Layout,
    pub(crate) renderer: &'a Renderer<'a>,
    pub(crate) observer: &'a dyn Observer,
    /// This run's manifest (the whole dataset's, or a shard's part) and where it is saved.
    pub(crate) own: Manifest,
    pub(crate) own_path: PathBuf,
    /// Images rendered (not kept) so far, and images finished or kept.
    pub(crate) rendered: usize,
    pub(crate) done: u64,
    pub(crate) message: String,
}

impl Ctx<'_> {
    /// Renders, telling the observer how far it is.
    fn render(&self, scene: &Scene, spp: u32, seed: u64, label: &str) -> Result<RenderOutput> {
        let mut progress = self.observer.render(label, spp);
        let pixels = scene.film.width as f64 * scene.film.height as f64;
        let start = std::time::Instant::now();
        let settings = RenderSettings { spp, seed, pixel_sampler: self.plan.pixel_sampler };
        let out = self.renderer.render(scene, &settings, &mut |done, _| {
            let rate = pixels * done as f64 / start.elapsed().as_secs_f64().max(1e-9) / 1e6;
            progress.update(done, rate);
        });
        drop(progress);
        let out = out?;
        if out.discarded_samples > 0 {
            self.note(format!("warning: {label}: {} non-finite path samples were discarded", out.discarded_samples));
        }
        Ok(out)
    }

    fn note(&self, line: String) {
        self.observer.note(&line);
    }

    /// One more image of the job is finished or kept.
    fn advance(&mut self) {
        self.done += 1;
        self.observer.progress(self.done, &self.message);
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
    let seed = render_seed(ctx.plan.seed, &job.name, v, "camera");
    let (pw, ph) = probe_size(&job.scene.film);
    let mut best: Option<(f64, Camera, u32)> = None;
    for attempt in 0..MAX_ATTEMPTS {
        let camera = jitter_camera(&job.scene.camera, &job.scene, seed.wrapping_add(attempt as u64));
        if camera.validate().is_err() {
            continue;
        }
        let mut probe = job.scene.clone();
        probe.camera = camera;
        let fraction = lit_fraction(ctx.renderer, &probe, seed ^ PROBE_SEED ^ attempt as u64)?;
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

/// One auxiliary image of a render.
fn aux_image(out: &RenderOutput, kind: AuxKind) -> &hush_dataset::Image {
    match kind {
        AuxKind::Albedo => &out.albedo,
        AuxKind::Normal => &out.normal,
        AuxKind::Diffuse => &out.diffuse,
        AuxKind::Specular => &out.specular,
    }
}

/// Where one noisy render's files go.
struct NoisyNames {
    file: String,
    aux: AuxFiles,
    variance: String,
}

impl NoisyNames {
    /// Render `k` of a view's ladder at `spp`: the noisy render (`k` = 0, in OIDN's layout) or repeat `k`.
    fn of(scene: &str, view: &str, spp: u32, k: u32) -> NoisyNames {
        match k {
            0 => NoisyNames {
                file: Layout::noisy_name(scene, view, spp),
                aux: AuxFiles::from_fn(|kind| Layout::noisy_aux_name(scene, view, spp, kind)),
                variance: Layout::noisy_variance_name(scene, view, spp),
            },
            _ => NoisyNames {
                file: Layout::repeat_name(scene, view, spp, k, "hdr"),
                aux: AuxFiles::from_fn(|kind| Layout::repeat_name(scene, view, spp, k, kind.extension())),
                variance: Layout::repeat_name(scene, view, spp, k, "var"),
            },
        }
    }
}

/// One noisy render: `kept` where a previous run finished it with these files, seed and sampler (its beauty,
/// its own features and its variance all valid), else rendered now and written. Whether it was rendered.
#[allow(clippy::too_many_arguments)]
fn noisy_render(
    ctx: &mut Ctx,
    scene: &Scene,
    camera: &CameraRecord,
    kept: Option<&RenderRecord>,
    names: NoisyNames,
    spp: u32,
    seed: u64,
    label: &str,
) -> Result<(RenderRecord, bool)> {
    let sampler = sampler_record(ctx.plan.pixel_sampler);
    let NoisyNames { file, aux: own, variance } = names;
    // A render is kept with its own features; one from before they were stored is rendered again.
    // Its variance file, where it has one (renders from before those were stored have none), must be
    // valid too: `hush dataset check` checks it, and a re-run is what mends what the check finds.
    let finished = |r: &&RenderRecord| {
        let files =
            std::iter::once(file.as_str()).chain(AuxKind::ALL.map(|k| own.file(k))).chain(r.variance.as_deref());
        r.file == file
            && r.aux.as_ref() == Some(&own)
            && r.pixel_sampler == sampler
            && files.into_iter().all(|f| ctx.valid(f, camera))
    };
    if let Some(r) = kept.filter(finished) {
        return Ok((r.clone(), false));
    }
    let out = ctx.render(scene, spp, seed, &format!("{label} {spp} spp"))?;
    for kind in AuxKind::ALL {
        write_rgb(ctx.layout.path(own.file(kind)), aux_image(&out, kind))?;
    }
    write_rgb(ctx.layout.path(&variance), &out.color_variance)?;
    write_rgb(ctx.layout.path(&file), &out.color)?;
    ctx.rendered += 1;
    let record = RenderRecord {
        spp,
        seed,
        file,
        render_seconds: out.seconds,
        aux: Some(own),
        variance: Some(variance),
        pixel_sampler: sampler,
    };
    Ok((record, true))
}

/// Renders (or keeps) every image of one view.
pub(crate) fn render_view(ctx: &mut Ctx, known: &Manifest, job: &JobScene, v: u32, split: Split) -> Result<()> {
    let plan = ctx.plan;
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
        let seed = render_seed(plan.seed, name, v, "camera");
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
        repeats: Vec::new(),
    };

    let sampler = sampler_record(plan.pixel_sampler);
    let spps = plan.ladder();
    // A test view renders the ladder `test_repeats` times in all (repeat k ≥ 1 with other seeds, under
    // repeats/), so that an evaluation can average over renders.
    let renders = if split == Split::Test { plan.test_repeats.max(1) } else { 1 };
    if renders > 1 {
        std::fs::create_dir_all(ctx.layout.path(Layout::REPEATS))
            .with_context(|| format!("creating {}", ctx.layout.path(Layout::REPEATS).display()))?;
    }
    for k in 0..renders {
        let repeat = k as usize;
        if repeat > 0 {
            progress.repeats.push(Vec::new());
        }
        for &spp in &spps {
            let seed = match k {
                0 => render_seed(plan.seed, name, v, &format!("noisy-{spp}")),
                _ => render_seed(plan.seed, name, v, &format!("noisy-{spp}-repeat-{k}")),
            };
            let recorded =
                previous.as_ref().and_then(|p| if repeat == 0 { Some(&p.noisy) } else { p.repeats.get(repeat - 1) });
            let kept = recorded.and_then(|ladder| ladder.iter().find(|r| r.spp == spp && r.seed == seed));
            let label = if repeat == 0 { label.clone() } else { format!("{label} repeat {k}") };
            let names = NoisyNames::of(name, &view, spp, k);
            let (record, rendered) = noisy_render(ctx, &scene, &camera, kept, names, spp, seed, &label)?;
            match repeat {
                0 => progress.noisy.push(record),
                _ => progress.repeats[repeat - 1].push(record),
            }
            if rendered {
                ctx.record(&progress)?;
            }
            ctx.advance();
        }
    }

    let clean = AuxFiles::from_fn(|kind| Layout::aux_name(name, &view, kind));
    let aux_seed = render_seed(plan.seed, name, v, "aux");
    let kept = previous.as_ref().and_then(|p| p.aux.clone()).filter(|a| {
        a.spp == plan.aux_spp
            && a.seed == aux_seed
            && a.max_depth == Some(scene.max_depth)
            && a.files == clean
            && a.pixel_sampler == sampler
            && AuxKind::ALL.iter().all(|&k| ctx.valid(clean.file(k), &camera))
    });
    let aux = match kept {
        Some(a) => a,
        None => {
            // At the scene's depth: the features follow mirrors and glass to the surface seen through them
            // (at depth 1 those would have none, unlike the noisy renders' own features).
            let out = ctx.render(&scene, plan.aux_spp, aux_seed, &format!("{label} features"))?;
            for kind in AuxKind::ALL {
                write_rgb(ctx.layout.path(clean.file(kind)), aux_image(&out, kind))?;
            }
            ctx.rendered += 1;
            AuxRecord {
                spp: plan.aux_spp,
                seed: aux_seed,
                render_seconds: out.seconds,
                max_depth: Some(scene.max_depth),
                files: clean,
                pixel_sampler: sampler.clone(),
            }
        }
    };
    progress.aux = Some(aux);
    ctx.record(&progress)?;
    ctx.advance();

    let (ref_spp, ss) = reference_sampling(plan.ref_spp_of(split), plan.ref_supersample, scene.film.filter);
    let ref_file = Layout::reference_name(name, &view);
    let ref_seed = render_seed(plan.seed, name, v, "reference");
    let kept = previous.as_ref().and_then(|p| p.reference.clone()).filter(|r| {
        r.spp == ref_spp
            && r.seed == ref_seed
            && r.supersample == ss
            && r.firefly.factor == plan.firefly_factor
            && r.file == ref_file
            && r.pixel_sampler == sampler
            && ctx.valid(&ref_file, &camera)
    });
    let (mut reference, mut reference_image) = match kept {
        Some(r) => (r, None),
        None => {
            let mut big = scene.clone();
            big.film.width *= ss;
            big.film.height *= ss;
            let out = ctx.render(&big, ref_spp, ref_seed, &format!("{label} reference {ss}x{ss}"))?;
            let mut color = out.color;
            let stats = if plan.firefly_factor > 0.0 {
                despeckle(&mut color, plan.firefly_factor)?
            } else {
                hush_dataset::DespeckleStats { clamped_pixels: 0, energy_removed: 0.0 }
            };
            let image = color.downsample_box(ss as usize)?;
            write_rgb(ctx.layout.path(&ref_file), &image)?;
            ctx.rendered += 1;
            let record = ReferenceRecord {
                spp: ref_spp,
                seed: ref_seed,
                file: ref_file.clone(),
                render_seconds: out.seconds,
                supersample: ss,
                firefly: FireflyRecord {
                    factor: plan.firefly_factor,
                    clamped_pixels: stats.clamped_pixels,
                    energy_removed: stats.energy_removed,
                },
                check: None,
                pixel_sampler: sampler.clone(),
            };
            (record, Some(image))
        }
    };
    progress.reference = Some(reference.clone());
    if plan.ref_check_spp > 0 {
        ctx.record(&progress)?;
    }
    ctx.advance();

    if plan.ref_check_spp > 0 {
        let seed = render_seed(plan.seed, name, v, "reference-check");
        if reference.check.as_ref().is_none_or(|c| c.spp != plan.ref_check_spp || c.seed != seed) {
            let out = ctx.render(&scene, plan.ref_check_spp, seed, &format!("{label} reference check"))?;
            let image = match reference_image.take() {
                Some(i) => i,
                None => read_rgb(ctx.layout.path(&ref_file))?,
            };
            let rel_mse = hush_eval::rel_mse(&image, &out.color)?;
            reference.check =
                Some(ReferenceCheck { spp: plan.ref_check_spp, seed, render_seconds: out.seconds, rel_mse });
            ctx.rendered += 1;
        }
        ctx.advance();
    }
    let check = reference.check.as_ref().map(|c| format!(", reference relMSE {:.2e}", c.rel_mse)).unwrap_or_default();
    progress.reference = Some(reference);
    ctx.record(&progress)?;
    ctx.note(format!("{label}: done ({split:?}{check})"));
    Ok(())
}
