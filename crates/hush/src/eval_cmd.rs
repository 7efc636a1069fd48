//! `hush eval`: every method on every test view and spp, the error-against-time comparison, pictures and
//! the report.
//!
//! A method turns a view's noisy input into a test image: the noisy input itself (raw path tracing, always
//! evaluated), each `--model`, and the baselines named with `--baseline` (see [`BASELINES`]). Adding a
//! baseline is one `impl Method` and one arm in [`baseline`].

use std::path::Path;

use anyhow::{Context, Result, bail};
use hush_dataset::{Image, Manifest, Split, ViewImages, load_view, write_atomic, write_png_preview};
use hush_eval::external;
use hush_eval::guided::{GuidedParams, guided_filter};
use hush_eval::pictures::{self, Rgb8};
use hush_eval::{
    Figure, FigureImage, FigureKind, NOISY, REFERENCE, Report, Row, Skipped, compare, exposure_of, time_median,
};

use crate::cli::EvalArgs;
use crate::denoiser::{Denoiser, aux_of};

/// What produced one test image, and how.
trait Method {
    /// The name in the report.
    fn name(&self) -> &str;
    /// The test image for `images.color`, and the median seconds of `timing_runs` warm denoising runs
    /// (`None` when nothing is denoised); or why the method cannot run here.
    fn run(&self, images: &ViewImages, timing_runs: usize) -> Result<Run>;
}

/// What a [`Method`] made of one view.
enum Run {
    Done(Image, Option<f64>),
    /// The method cannot run on this machine (e.g. a Python package is missing): reported once, skipped after.
    Skipped(Skipped),
}

/// The hand-coded baseline: hush-eval's albedo- and normal-guided cross-bilateral filter.
struct Guided;

impl Method for Guided {
    fn name(&self) -> &str {
        "guided"
    }

    fn run(&self, images: &ViewImages, timing_runs: usize) -> Result<Run> {
        let params = GuidedParams::default();
        let filter = || Ok(guided_filter(&images.color, Some(&images.albedo), Some(&images.normal), &params)?);
        let (image, seconds) = timed(timing_runs, filter)?;
        Ok(Run::Done(image, Some(seconds)))
    }
}

/// BM3D or official OIDN 2.5.1 in the baselines' Python venv (`cargo xtask baselines setup`); the runner
/// measures its own warm median seconds.
struct External(external::Baseline);

impl Method for External {
    fn name(&self) -> &str {
        self.0.name()
    }

    fn run(&self, images: &ViewImages, timing_runs: usize) -> Result<Run> {
        let input =
            external::Input { color: &images.color, albedo: Some(&images.albedo), normal: Some(&images.normal) };
        match external::run_baseline(self.0, &[input], &external::venv_python(), timing_runs.max(1))? {
            external::Outcome::Done { mut images, seconds, .. } => match (images.pop(), seconds.first()) {
                (Some(image), Some(&s)) => Ok(Run::Done(image, Some(s))),
                _ => bail!("{} returned no image", self.0.name()),
            },
            external::Outcome::Skipped { reason, install } => {
                Ok(Run::Skipped(Skipped { method: self.0.name().into(), reason, install: Some(install.into()) }))
            }
        }
    }
}

/// Official OIDN 2.5.1 in this process through the `oidn` crate (cargo feature `oidn`), with the settings of
/// the Python runner, so its time has no process or interpreter overhead.
#[cfg(feature = "oidn")]
struct NativeOidn;

#[cfg(feature = "oidn")]
impl Method for NativeOidn {
    fn name(&self) -> &str {
        external::Baseline::Oidn.name()
    }

    fn run(&self, images: &ViewImages, timing_runs: usize) -> Result<Run> {
        let (image, seconds) = hush_eval::oidn_native::denoise(
            &images.color,
            Some(&images.albedo),
            Some(&images.normal),
            timing_runs.max(1),
        )?;
        Ok(Run::Done(image, Some(seconds)))
    }
}

/// Raw path tracing: the noisy input as it is.
struct Noisy;

impl Method for Noisy {
    fn name(&self) -> &str {
        NOISY
    }

    fn run(&self, images: &ViewImages, _: usize) -> Result<Run> {
        Ok(Run::Done(images.color.clone(), None))
    }
}

/// A hush model (or OIDN weights) run by hush.
struct Model {
    name: String,
    denoiser: Denoiser,
}

impl Method for Model {
    fn name(&self) -> &str {
        &self.name
    }

    fn run(&self, images: &ViewImages, timing_runs: usize) -> Result<Run> {
        let aux: Vec<&Image> = self.denoiser.features().iter().map(|&f| aux_of(images, f)).collect();
        let (image, seconds) = timed(timing_runs, || self.denoiser.denoise(&images.color, &aux))?;
        Ok(Run::Done(image, Some(seconds)))
    }
}

/// Runs `denoise` once (the warm-up, whose output is kept), then `runs` more times, and returns the output
/// and the median seconds of the timed runs.
fn timed(runs: usize, denoise: impl Fn() -> Result<Image>) -> Result<(Image, f64)> {
    let image = denoise()?;
    let mut failure = None;
    let timing = time_median(runs, 0, || {
        if let Err(e) = denoise() {
            failure.get_or_insert(e);
        }
    });
    match failure {
        Some(e) => Err(e.context("a timed denoising run failed after the first succeeded")),
        None => Ok((image, timing.median)),
    }
}

/// The names `--baseline` accepts, with what they are (`all` asks for every one).
pub const BASELINES: &[(&str, &str)] = &[
    (NOISY, "the noisy input (raw path tracing); always evaluated"),
    ("guided", "hush's hand-coded cross-bilateral filter guided by albedo and normal"),
    (
        "oidn",
        "official Open Image Denoise 2.5.1 (Python venv of `cargo xtask baselines setup`, in process with the `oidn` feature)",
    ),
    ("bm3d", "BM3D on the tonemapped image (Python venv of `cargo xtask baselines setup`)"),
];

/// The baseline called `name`; `None` for `noisy`, which is always evaluated. A new baseline is a name in
/// [`BASELINES`], a [`Method`] and an arm here; one that cannot run returns [`Run::Skipped`].
fn baseline(name: &str) -> Result<Option<Box<dyn Method>>> {
    Ok(Some(match name {
        NOISY => return Ok(None),
        "guided" => Box::new(Guided),
        #[cfg(feature = "oidn")]
        "oidn" => Box::new(NativeOidn),
        #[cfg(not(feature = "oidn"))]
        "oidn" => Box::new(External(external::Baseline::Oidn)),
        "bm3d" => Box::new(External(external::Baseline::Bm3d)),
        _ => {
            let known: Vec<String> = BASELINES.iter().map(|(n, what)| format!("{n} ({what})")).collect();
            bail!("unknown baseline '{name}': known baselines are {} (`all` asks for every one)", known.join(", "))
        }
    }))
}

/// A method name for a model file: `<run folder>/<file stem>`.
fn method_name(path: &Path) -> String {
    let stem = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    match path.parent().and_then(|p| p.file_name()) {
        Some(dir) => format!("{}/{stem}", dir.to_string_lossy()),
        None => stem,
    }
}

pub fn run(args: EvalArgs) -> Result<()> {
    let manifest = Manifest::load(&args.dataset)?;
    let views: Vec<_> = manifest.split(Split::Test).cloned().collect();
    if views.is_empty() {
        bail!("{} has no test views: render the dataset with --test-views 1 or more", args.dataset.display());
    }
    let mut report = Report::default();
    let mut methods: Vec<Box<dyn Method>> = vec![Box::new(Noisy)];
    for path in &args.models {
        let (name, denoiser) = (method_name(path), Denoiser::load(path)?);
        let info = &denoiser.info;
        report.notes.push(format!("Model {name}: {} on features {}.", info.net.describe(), info.features));
        methods.push(Box::new(Model { name, denoiser }));
    }
    let all: Vec<String> = BASELINES.iter().map(|(name, _)| name.to_string()).collect();
    let baselines = if args.baselines.iter().any(|b| b == "all") { &all } else { &args.baselines };
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
    let previews = args.out.join("previews");
    let picture_dir = args.out.join("pictures");
    for dir in [&previews, &picture_dir] {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }

    report.notes.insert(0, format!("Dataset: {}; test views: {}.", args.dataset.display(), views.len()));
    report.notes.push(format!(
        "Machine: {}{} logical CPUs{}; denoise time is the median of {} warm runs on {}; render times are those \
         the dataset's manifest recorded on the machine that rendered it.",
        cpu_model().map(|m| format!("{m}, ")).unwrap_or_default(),
        std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1),
        std::env::var("RAYON_NUM_THREADS").map(|n| format!(", RAYON_NUM_THREADS={n}")).unwrap_or_default(),
        args.timing_runs.max(1),
        if cfg!(feature = "cuda") { "CUDA" } else { "the CPU" }
    ));
    report.notes.push("PNG previews of every image are in previews/ beside report.md.".into());

    for view in &views {
        let name = format!("{}_{}", view.scene, view.view);
        let spps: Vec<u32> =
            view.noisy.iter().map(|r| r.spp).filter(|s| args.spp.is_empty() || args.spp.contains(s)).collect();
        let Some(&picture_spp) = spps.iter().min() else {
            bail!("view {name} has no noisy render at the requested spp {:?}", args.spp);
        };
        let mut reference_row = true;
        for spp in spps {
            let images = load_view(&args.dataset, view, spp)?;
            let exposure = exposure_of(&images.reference)?;
            let preview = |method: &str, image: &Image| -> Result<String> {
                let file = format!("{name}_{spp:06}_{}.png", file_safe(method));
                write_png_preview(previews.join(&file), image, exposure)?;
                Ok(format!("previews/{file}"))
            };
            if std::mem::take(&mut reference_row) {
                let mut row =
                    Row::new(&name, REFERENCE, view.reference.spp, &compare(&images.reference, &images.reference)?);
                row.render_seconds = Some(view.reference.render_seconds);
                row.preview = Some(preview(REFERENCE, &images.reference)?);
                report.rows.push(row);
            }
            let render_seconds = view.noisy_at(spp).map(|r| r.render_seconds);
            let mut outputs: Vec<(String, Image)> = Vec::new();
            for method in &methods {
                if report.skipped.iter().any(|k| k.method == method.name()) {
                    continue;
                }
                let run = method
                    .run(&images, args.timing_runs)
                    .with_context(|| format!("{} on {name} at {spp} spp", method.name()))?;
                let (image, denoise_seconds) = match run {
                    Run::Done(image, seconds) => (image, seconds),
                    Run::Skipped(skipped) => {
                        eprintln!("{}: skipped: {}", skipped.method, skipped.reason);
                        report.skipped.push(skipped);
                        continue;
                    }
                };
                let mut row = Row::new(&name, method.name(), spp, &compare(&image, &images.reference)?);
                row.render_seconds = render_seconds;
                row.denoise_seconds = denoise_seconds;
                row.preview = Some(preview(method.name(), &image)?);
                report.rows.push(row);
                if spp == picture_spp {
                    outputs.push((method.name().to_string(), image));
                }
            }
            if spp == picture_spp {
                report.figures.extend(pictures_of(&picture_dir, &name, spp, &outputs, &images.reference, exposure)?);
            }
        }
    }
    report.write(&args.out)?;
    eprintln!("report: {}", args.out.join(Report::HTML_FILE).display());
    eprintln!("report: {}", args.out.join(Report::MARKDOWN_FILE).display());
    Ok(())
}

/// The crops side by side (each output, then the reference) and the difference pictures of one view,
/// written to `dir` (`pictures/` of the report).
fn pictures_of(
    dir: &Path,
    view: &str,
    spp: u32,
    outputs: &[(String, Image)],
    reference: &Image,
    exposure: f32,
) -> Result<Vec<Figure>> {
    let Some((_, noisy)) = outputs.iter().find(|(m, _)| m == NOISY) else { return Ok(Vec::new()) };
    let side = (reference.width.min(reference.height) / 2).clamp(1, 128);
    let zoom = (256 / side).clamp(1, 8);
    let (x, y) = pictures::worst_window(noisy, reference, exposure, side)?;
    let write = |file: String, picture: &Rgb8| -> Result<String> {
        let path = dir.join(&file);
        let png = picture.to_png()?;
        write_atomic(&path, |tmp| std::fs::write(tmp, &png).with_context(|| format!("writing {}", path.display())))?;
        Ok(format!("pictures/{file}"))
    };
    let mut crops = Vec::new();
    let mut diffs = Vec::new();
    let diff_zoom = (256 / reference.width.max(1)).clamp(1, 4);
    for (method, image) in outputs.iter().map(|(m, i)| (m.as_str(), i)).chain([(REFERENCE, reference)]) {
        let crop = Rgb8::tonemapped(image, exposure)?.crop(x, y, side, side).upscale(zoom);
        let path = write(format!("{view}_{spp:06}_{}_crop.png", file_safe(method)), &crop)?;
        crops.push(FigureImage { method: Some(method.to_string()), ..FigureImage::new(method, path) });
        if method != REFERENCE {
            let (picture, marks) = pictures::error_marks(image, reference, exposure)?;
            let path = write(format!("{view}_{spp:06}_{}_diff.png", file_safe(method)), &picture.upscale(diff_zoom))?;
            let caption =
                format!("{method}: {:.1} % > 3 %, {:.1} % > 10 %", 100.0 * marks.over_low, 100.0 * marks.over_high);
            diffs.push(FigureImage {
                method: Some(method.to_string()),
                marks: Some(marks),
                ..FigureImage::new(caption, path)
            });
        }
    }
    Ok(vec![
        Figure {
            title: format!("{view} at {spp} spp: crops"),
            kind: FigureKind::Crops { view: view.to_string(), spp },
            images: crops,
            note: format!(
                "The {side}×{side} window at ({x}, {y}) where the noisy input is worst, tonemapped as the metrics \
                 are, enlarged {zoom}×."
            ),
        },
        Figure {
            title: format!("{view} at {spp} spp: pixels off by more than 3 % and 10 %"),
            kind: FigureKind::Differences { view: view.to_string(), spp },
            images: diffs,
            note: "Yellow: the tonemapped value of some channel is off by more than 3 % of the range; red: by more \
                   than 10 % (the thresholds of the thesis's figures 7.7 and 7.3); grey: the reference, dimmed."
                .into(),
        },
    ])
}

/// The CPU's model name (Linux's /proc/cpuinfo), if known.
fn cpu_model() -> Option<String> {
    let info = std::fs::read_to_string("/proc/cpuinfo").ok()?;
    let line = info.lines().find(|l| l.starts_with("model name"))?;
    Some(line.split_once(':')?.1.trim().to_string())
}

/// A method name as part of a file name: `/` and other unsafe characters become `-`.
fn file_safe(method: &str) -> String {
    method.chars().map(|c| if c.is_ascii_alphanumeric() || "._-".contains(c) { c } else { '-' }).collect()
}
