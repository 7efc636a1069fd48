//! Evaluation: every method on every test view and spp of a dataset, against the reference, with the
//! error-against-time comparison, pictures and the report (hush-eval's `Report`).
//!
//! A method turns a view's noisy input into a test image: the noisy input itself (raw path tracing, always
//! evaluated), each model, and the baselines named in the plan (see [`BASELINES`]).

mod denoiser;
mod methods;
mod pictures;

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use hush_dataset::{AuxSource, Image, Manifest, Split, load_render_with, write_png_preview};
use hush_eval::viewer::file_safe;
use hush_eval::{REFERENCE, Report, Row, Viewer, compare, exposure_of};

pub use denoiser::{Denoiser, aux_of, blend_input, combine, keep_exact};
pub use methods::{BASELINES, Method, Model, Run, baseline, method_name};

use crate::Observer;
use crate::official::{OIDN_VERSION, official_for};
use methods::Noisy;
use pictures::pictures_of;

/// What to evaluate: every option of `hush eval`.
#[derive(Clone, Debug, PartialEq)]
pub struct EvalPlan {
    /// The dataset whose test split is evaluated.
    pub dataset: PathBuf,
    /// Trained models (`.safetensors`, or OIDN's `.tza` weights); `a.safetensors+b.safetensors` (where no file
    /// has that name) is one method, the mean of those models' outputs.
    pub models: Vec<PathBuf>,
    /// Baselines by name ([`BASELINES`]; `all` for every one); `noisy` is always evaluated.
    pub baselines: Vec<String>,
    /// Noisy inputs at these spp (empty: all stored ones).
    pub spp: Vec<u32>,
    /// The report folder.
    pub out: PathBuf,
    /// Denoise time is the median of this many warm runs.
    pub timing_runs: usize,
    /// Which auxiliary images the denoisers get with each noisy input: its own (default) or the view's clean
    /// ones.
    pub aux: AuxSource,
    /// Also evaluate OIDN's official weights (built in, run by hush) for each feature set among the models
    /// (color + albedo + normal without models): the generic model every hush model must beat.
    pub official: bool,
    /// Evaluate the views of these scenes, of either split, instead of the test split: training scenes held
    /// out of training as a validation split (`hush train --validation`) choose among models without the test
    /// scenes seeing the choice. Empty: the test split.
    pub scenes: Vec<String>,
    /// Where the networks run: `cpu` or `cuda` ([`crate::device`]; `None`: CUDA when built with it).
    pub device: Option<String>,
    /// After every network hush runs (its models and OIDN's official weights alike; not the `oidn` baseline,
    /// OIDN's own runtime), write back the pixels whose every sample agreed ([`hush_net::keep_exact_pixels`]),
    /// where the dataset stores the render's variance (a variance file that cannot be read is noted and skipped).
    pub keep_exact: bool,
    /// After every network hush runs (as `keep_exact`, and before it), mix the noisy input back in by each
    /// pixel's standard error ([`hush_net::blend_input`]) with this relative error of the network, where the
    /// dataset stores the render's variance. `None`: the networks' output as it is.
    pub blend_input: Option<f32>,
    /// Run every network hush runs in this many poses of the square's symmetries and average them
    /// ([`Denoiser::denoise_poses`]: 1 the network as it is, 2 with the x flip, 4 the flips, 8 the flips and
    /// transposes); the time is that of all of them.
    pub poses: usize,
    /// Where a method has several outputs (poses or ensemble members), put back the input's low band where they
    /// disagree, at this Gaussian std in pixels ([`hush_net::ensemble::restore_low_band`]), where the dataset
    /// stores the render's variance. `None`: their mean as it is.
    pub restore_low_band: Option<f32>,
}

impl EvalPlan {
    pub const DEFAULT_TIMING_RUNS: usize = 3;

    /// Evaluates `models` (and the noisy input) on `dataset`'s test split into `out`, with the defaults.
    pub fn new(dataset: impl Into<PathBuf>, models: Vec<PathBuf>, out: impl Into<PathBuf>) -> Self {
        EvalPlan {
            dataset: dataset.into(),
            models,
            baselines: Vec::new(),
            spp: Vec::new(),
            out: out.into(),
            timing_runs: Self::DEFAULT_TIMING_RUNS,
            aux: AuxSource::default(),
            official: true,
            scenes: Vec::new(),
            device: None,
            keep_exact: true,
            blend_input: None,
            poses: 1,
            restore_low_band: None,
        }
    }
}

/// The views `plan` evaluates: the test split, or every view of `plan.scenes` (an unknown scene is an error
/// listing the dataset's scenes).
fn evaluated_views(manifest: &Manifest, plan: &EvalPlan) -> Result<Vec<hush_dataset::ViewRecord>> {
    if plan.scenes.is_empty() {
        let views: Vec<_> = manifest.split(Split::Test).cloned().collect();
        if views.is_empty() {
            bail!("{} has no test views: render the dataset with --test-views 1 or more", plan.dataset.display());
        }
        return Ok(views);
    }
    for name in &plan.scenes {
        if !manifest.views.iter().any(|v| &v.scene == name) {
            let mut scenes: Vec<&str> = manifest.views.iter().map(|v| v.scene.as_str()).collect();
            scenes.sort_unstable();
            scenes.dedup();
            bail!("--scenes {name}: {} has no such scene; it has {}", plan.dataset.display(), scenes.join(", "));
        }
    }
    Ok(manifest.views.iter().filter(|v| plan.scenes.contains(&v.scene)).cloned().collect())
}

/// Evaluates the methods `plan` asks for on the test split of its dataset and writes the report into
/// `plan.out`; returns the report.
pub fn evaluate(plan: &EvalPlan, observer: &dyn Observer) -> Result<Report> {
    let manifest = Manifest::load(&plan.dataset)?;
    let views = evaluated_views(&manifest, plan)?;
    let device = crate::device(plan.device.as_deref())?;
    let mut report = Report::default();
    let mut methods: Vec<Box<dyn Method>> = vec![Box::new(Noisy)];
    let mut sets: Vec<hush_net::InputFeatures> = Vec::new();
    for path in &plan.models {
        let name = method_name(path);
        let members = methods::ensemble_members(path).unwrap_or_else(|| vec![path.clone()]);
        let mut denoisers = Vec::new();
        let member_names = methods::member_names(&members);
        for (member, member_name) in members.iter().zip(&member_names) {
            let denoiser = Denoiser::load_on(member, &device)?;
            let info = &denoiser.info;
            let what = format!("{} on features {}", info.net.describe(), info.features);
            report.notes.push(match members.len() {
                1 => format!("Model {name}: {what}."),
                n => format!("Model {name}, the mean of {n} models' outputs: {member_name} is a {what}."),
            });
            if !sets.contains(&info.features) {
                sets.push(info.features.clone());
            }
            denoisers.push(denoiser);
        }
        methods.push(Box::new(Model {
            name,
            denoisers,
            keep_exact: plan.keep_exact,
            blend_input: plan.blend_input,
            poses: plan.poses,
            restore_low_band: plan.restore_low_band,
        }));
    }
    if plan.official {
        if sets.is_empty() {
            sets.push(crate::train::parse_features(crate::train::DEFAULT_FEATURES)?);
        }
        let mut names = Vec::new();
        for features in &sets {
            let weights = official_for(features);
            if names.contains(&weights.name) {
                continue;
            }
            names.push(weights.name);
            report.notes.push(format!(
                "{}: Open Image Denoise {OIDN_VERSION}'s official weights for {}, run by hush (bit-exact with OIDN's \
                 runtime on its golden inputs).",
                weights.method_name(),
                weights.features()
            ));
            methods.push(Box::new(Model {
                name: weights.method_name(),
                denoisers: vec![Denoiser::official_on(&weights, &device)?],
                keep_exact: plan.keep_exact,
                blend_input: plan.blend_input,
                poses: plan.poses,
                restore_low_band: plan.restore_low_band,
            }));
        }
    }
    let all: Vec<String> = BASELINES.iter().map(|(name, _)| name.to_string()).collect();
    let baselines = if plan.baselines.iter().any(|b| b == "all") { &all } else { &plan.baselines };
    for name in baselines {
        if let Some(method) = baseline(name)? {
            methods.push(method);
        }
    }
    for (i, m) in methods.iter().enumerate() {
        if methods[..i].iter().any(|other| other.name() == m.name()) || m.name() == REFERENCE {
            bail!("two methods are called '{}': give the models distinct folder or file names", m.name());
        }
    }
    let previews = plan.out.join("previews");
    let picture_dir = plan.out.join("pictures");
    for dir in [&previews, &picture_dir] {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }

    report.notes.insert(
        0,
        format!(
            "Dataset: {}; {}: {}; auxiliary inputs: {} (`--aux {}`); the noisy inputs' pixel positions: {}.",
            hush_eval::shown_path(&plan.dataset),
            if plan.scenes.is_empty() {
                "test views".to_string()
            } else {
                format!("views of the scenes {} (chosen by `--scenes`, not the test split)", plan.scenes.join(", "))
            },
            views.len(),
            plan.aux.describe(),
            plan.aux,
            pixel_positions(&views)
        ),
    );
    let most = views.iter().map(|v| 1 + v.repeats.len()).max().unwrap_or(1);
    if most > 1 {
        let least = views.iter().map(|v| 1 + v.repeats.len()).min().unwrap_or(1);
        let count = if least == most { most.to_string() } else { format!("{least} to {most}") };
        report.notes.push(format!(
            "Each case is scored by the mean of each metric over {count} renders of its noisy input with independent \
             seeds (the dataset's and its repeats, `hush dataset --test-repeats`): where a light is smaller than a \
             pixel, one render decides a PSNR by a few pixels. summary.json lists each render's PSNR \
             (`psnr_renders`); times, previews and pictures are the first render's."
        ));
    }
    report.notes.push(format!(
        "Machine: {}{} logical CPUs{}; denoise time is the median of {} warm runs on {}; render times are those \
         the dataset's manifest recorded on the machine that rendered it.",
        cpu_model().map(|m| format!("{m}, ")).unwrap_or_default(),
        std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1),
        std::env::var("RAYON_NUM_THREADS").map(|n| format!(", RAYON_NUM_THREADS={n}")).unwrap_or_default(),
        plan.timing_runs.max(1),
        if cfg!(feature = "cuda") { "CUDA" } else { "the CPU" }
    ));
    report.notes.push("PNG previews of every image are in previews/ beside report.md.".into());

    // A model that takes the variance needs it; keeping exact pixels only uses it where it reads.
    let variance_needed = methods.iter().any(|m| m.needs_variance());
    let variance_wanted = plan.keep_exact || plan.blend_input.is_some() || plan.restore_low_band.is_some();
    let mut unreadable_variance = Vec::new();
    if plan.keep_exact {
        report.notes.push(
            "After each network hush runs (its models and OIDN's official weights alike; the `oidn` baseline is OIDN's \
             own runtime, left as it is), pixels whose every sample \
             agreed are the noisy input's (`--keep-exact`, on by default): a pixel with variance 0 in every channel \
             and a positive color, whose 8 neighbours are such pixels too (a constant sky or an emitter seen \
             directly), where the dataset stores the render's variance and some pixel has a variance above 0."
                .into(),
        );
    }
    if let Some(tau) = plan.blend_input {
        report.notes.push(format!(
            "After each network hush runs, before keeping exact pixels, the noisy input is mixed back in by each \
             pixel's standard error (`--blend-input {tau}`): its weight is τ²L²/(τ²L² + s²), with τ = {tau} the \
             network's assumed relative error, L the denoised pixel's level and s² the render's variance of the \
             pixel's mean averaged over its 5×5 window, where the dataset stores the render's variance."
        ));
    }
    if plan.poses > 1 {
        report.notes.push(format!(
            "Each network hush runs (its models and OIDN's official weights alike) denoises every input in {} poses \
             of the square's symmetries (`--poses {}`: {}), turned back and averaged; its time is that of all of \
             them.",
            plan.poses,
            plan.poses,
            hush_net::ensemble::POSE_NAMES[..plan.poses.min(hush_net::ensemble::POSES)].join(", ")
        ));
    }
    if let Some(sigma) = plan.restore_low_band {
        report.notes.push(format!(
            "Where a method's outputs are several (poses or ensemble members), the noisy input's low band (Gaussian \
             std {sigma} px) is put back after their mean where they disagree (`--restore-low-band {sigma}`): \
             weight e²/(e² + s²), e² the outputs' sample variance in that band and s² the input's, from the \
             render's variance, where the dataset stores it; values clamped at the display's white point."
        ));
    }
    for view in &views {
        let name = format!("{}_{}", view.scene, view.view);
        let spps: Vec<u32> =
            view.noisy.iter().map(|r| r.spp).filter(|s| plan.spp.is_empty() || plan.spp.contains(s)).collect();
        let Some(&picture_spp) = spps.iter().min() else {
            bail!("view {name} has no noisy render at the requested spp {:?}", plan.spp);
        };
        let mut reference_row = true;
        // Read once per view, not once per render.
        let mut reference: Option<Image> = None;
        for spp in spps {
            // The dataset's noisy render, then its repeats (`hush dataset --test-repeats`): each method's
            // metrics are their means; times, previews and pictures are the first render's.
            let renders = view.renders_at(spp);
            let mut metrics: Vec<Vec<hush_eval::Metrics>> = vec![Vec::new(); methods.len()];
            let mut first: Vec<Option<(Option<f64>, String)>> = vec![None; methods.len()];
            for (i, &render) in renders.iter().enumerate() {
                let what =
                    if i == 0 { format!("{name} at {spp} spp") } else { format!("{name} at {spp} spp, repeat {i}") };
                let load = |variance: bool| {
                    load_render_with(&plan.dataset, view, render, plan.aux, variance, reference.clone())
                };
                let images = match load(variance_needed || variance_wanted) {
                    Err(e) if variance_wanted && !variance_needed => {
                        unreadable_variance.push(format!("{what} ({e})"));
                        load(false)?
                    }
                    loaded => loaded?,
                };
                if reference.is_none() {
                    reference = Some(images.reference.clone());
                }
                let exposure = exposure_of(&images.reference)?;
                let preview = |method: &str, image: &Image| -> Result<String> {
                    let file = format!("{name}_{spp:06}_{}.png", file_safe(method));
                    write_png_preview(previews.join(&file), image, exposure)?;
                    Ok(format!("previews/{file}"))
                };
                if i == 0 && std::mem::take(&mut reference_row) {
                    let mut row =
                        Row::new(&name, REFERENCE, view.reference.spp, &compare(&images.reference, &images.reference)?);
                    row.render_seconds = Some(view.reference.render_seconds);
                    row.preview = Some(preview(REFERENCE, &images.reference)?);
                    report.rows.push(row);
                }
                let mut outputs: Vec<(String, Image)> = Vec::new();
                for (m, method) in methods.iter().enumerate() {
                    if report.skipped.iter().any(|k| k.method == method.name()) {
                        continue;
                    }
                    // Repeats only score: one warm run each, untimed.
                    let runs = if i == 0 { plan.timing_runs } else { 1 };
                    let run = method.run(&images, runs).with_context(|| format!("{} on {what}", method.name()))?;
                    let (image, denoise_seconds) = match run {
                        Run::Done(image, seconds) => (image, seconds),
                        Run::Skipped(skipped) => {
                            observer.note(&format!("{}: skipped: {}", skipped.method, skipped.reason));
                            report.skipped.push(skipped);
                            continue;
                        }
                    };
                    metrics[m].push(compare(&image, &images.reference)?);
                    if i == 0 {
                        first[m] = Some((denoise_seconds, preview(method.name(), &image)?));
                        if spp == picture_spp {
                            outputs.push((method.name().to_string(), image));
                        }
                    }
                }
                if i == 0 && spp == picture_spp {
                    report.figures.extend(pictures_of(
                        &picture_dir,
                        &name,
                        spp,
                        &outputs,
                        &images.reference,
                        exposure,
                    )?);
                    report.viewers.push(Viewer::write(&plan.out, &name, spp, &outputs, &images.reference, exposure)?);
                }
            }
            let render_seconds = view.noisy_at(spp).map(|r| r.render_seconds);
            for (m, method) in methods.iter().enumerate() {
                // A method skipped on a later render is left out of the case: its mean would be over fewer renders.
                if report.skipped.iter().any(|k| k.method == method.name()) || metrics[m].len() != renders.len() {
                    continue;
                }
                let (Some((denoise_seconds, preview)), Some(mut row)) =
                    (first[m].take(), Row::of_renders(&name, method.name(), spp, &metrics[m]))
                else {
                    continue;
                };
                row.render_seconds = render_seconds;
                row.denoise_seconds = denoise_seconds;
                row.preview = Some(preview);
                report.rows.push(row);
            }
        }
    }
    if !unreadable_variance.is_empty() {
        let note = format!(
            "No exact pixels were kept where the render's variance file could not be read: {}. `hush dataset check` \
             names such files; `hush dataset` with the same arguments renders them again.",
            unreadable_variance.join("; ")
        );
        observer.note(&note);
        report.notes.push(note);
    }
    report.write(&plan.out)?;
    Ok(report)
}

/// The CPU's model name (Linux's /proc/cpuinfo), if known.
fn cpu_model() -> Option<String> {
    let info = std::fs::read_to_string("/proc/cpuinfo").ok()?;
    let line = info.lines().find(|l| l.starts_with("model name"))?;
    Some(line.split_once(':')?.1.trim().to_string())
}

/// How the evaluated noisy inputs placed their samples in each pixel, as the manifest records it.
fn pixel_positions(views: &[hush_dataset::ViewRecord]) -> String {
    let samplers: std::collections::BTreeSet<Option<&str>> = views
        .iter()
        .flat_map(|v| v.noisy.iter().chain(v.repeats.iter().flatten()))
        .map(|r| r.pixel_sampler.as_deref())
        .collect();
    let name = |s: &Option<&str>| s.unwrap_or("independent").to_string();
    match samplers.iter().collect::<Vec<_>>()[..] {
        [one] => format!("{} (`--pixel-sampler {}`)", name(one), name(one)),
        _ => format!("mixed ({})", samplers.iter().map(name).collect::<Vec<_>>().join(", ")),
    }
}
