//! The methods an evaluation compares: the noisy input (raw path tracing), models, and the baselines. Adding
//! a baseline is one `impl Method`, a name in [`BASELINES`] and one arm in [`baseline`].

use std::path::Path;

use anyhow::{Result, bail};
use hush_dataset::{Image, ViewImages};
use hush_eval::guided::{GuidedParams, guided_filter};
use hush_eval::{NOISY, Skipped, external, time_median};

use super::denoiser::{Denoiser, aux_of, blend_input, combine, keep_exact};

/// What produced one test image, and how.
pub trait Method {
    /// The name in the report.
    fn name(&self) -> &str;
    /// The test image for `images.color`, and the median seconds of `timing_runs` warm denoising runs
    /// (`None` when nothing is denoised); or why the method cannot run here.
    fn run(&self, images: &ViewImages, timing_runs: usize) -> Result<Run>;
    /// Whether it reads the noisy render's variance ([`ViewImages::variance`]).
    fn needs_variance(&self) -> bool {
        false
    }
}

/// What a [`Method`] made of one view.
pub enum Run {
    Done(Image, Option<f64>),
    /// The method cannot run on this machine (e.g. a Python package is missing): reported once, skipped after.
    Skipped(Skipped),
}

/// The hand-coded baseline: hush-eval's albedo- and normal-guided cross-bilateral filter.
pub struct Guided;

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
pub struct Noisy;

impl Method for Noisy {
    fn name(&self) -> &str {
        NOISY
    }

    fn run(&self, images: &ViewImages, _: usize) -> Result<Run> {
        Ok(Run::Done(images.color.clone(), None))
    }
}

/// A hush model (or OIDN weights) run by hush; or several, whose outputs are averaged (an ensemble: each
/// member gets its own auxiliary images; the mean of kernel-predicting members' outputs is again a weighted
/// average of the noisy input).
pub struct Model {
    pub name: String,
    pub denoisers: Vec<Denoiser>,
    /// Write back the pixels whose every sample agreed ([`super::denoiser::keep_exact`]) where the view has
    /// the render's variance (once, after the members' mean).
    pub keep_exact: bool,
    /// Mix the noisy input back in by each pixel's standard error, with this relative error of the network
    /// ([`hush_net::blend_input`]), where the view has the render's variance (after the members' mean, before
    /// keeping exact pixels).
    pub blend_input: Option<f32>,
    /// Each member runs in this many poses ([`Denoiser::denoise_poses`]); every output counts once in the mean.
    pub poses: usize,
    /// Where the outputs (members and poses) are several and the view has the render's variance, put back the
    /// input's low band where they disagree, at this Gaussian std in pixels
    /// ([`hush_net::ensemble::restore_low_band`]; after the mean, before blending the input).
    pub restore_low_band: Option<f32>,
}

impl Method for Model {
    fn name(&self) -> &str {
        &self.name
    }

    fn needs_variance(&self) -> bool {
        self.denoisers.iter().any(|d| d.features().contains(&hush_net::Feature::Variance))
    }

    fn run(&self, images: &ViewImages, timing_runs: usize) -> Result<Run> {
        let auxes = self
            .denoisers
            .iter()
            .map(|d| d.features().iter().map(|&f| aux_of(images, f)).collect::<Result<Vec<&Image>>>())
            .collect::<Result<Vec<_>>>()?;
        let variance = images.variance.as_ref();
        let (image, seconds) = timed(timing_runs, || {
            let mut outputs = Vec::new();
            for (denoiser, aux) in self.denoisers.iter().zip(&auxes) {
                outputs.extend(denoiser.denoise_poses(&images.color, aux, self.poses.max(1))?);
            }
            let (mut out, _) = combine(&outputs, &images.color, variance, self.restore_low_band)?;
            if let (Some(tau), Some(variance)) = (self.blend_input, variance) {
                blend_input(&mut out, &images.color, variance, tau)?;
            }
            if let Some(variance) = variance.filter(|_| self.keep_exact) {
                keep_exact(&mut out, &images.color, variance)?;
            }
            Ok(out)
        })?;
        Ok(Run::Done(image, Some(seconds)))
    }
}

/// Names for an ensemble's members: [`method_name`]s where they tell the members apart, else the paths as
/// given (without the extension).
pub fn member_names(members: &[std::path::PathBuf]) -> Vec<String> {
    let short: Vec<String> = members.iter().map(|m| method_name(m)).collect();
    if short.iter().collect::<std::collections::HashSet<_>>().len() == short.len() {
        return short;
    }
    members.iter().map(|m| m.with_extension("").display().to_string()).collect()
}

/// The members of an ensemble written `a.safetensors+b.safetensors`: `None` where `path` names a file (a `+` in a
/// file's name stays its name) or has no `+`.
pub fn ensemble_members(path: &Path) -> Option<Vec<std::path::PathBuf>> {
    let text = path.to_str()?;
    if path.exists() || !text.contains('+') {
        return None;
    }
    Some(text.split('+').map(std::path::PathBuf::from).collect())
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
pub fn baseline(name: &str) -> Result<Option<Box<dyn Method>>> {
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
pub fn method_name(path: &Path) -> String {
    if let Some(members) = ensemble_members(path) {
        return member_names(&members).join("+");
    }
    let stem = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    match path.parent().and_then(|p| p.file_name()) {
        Some(dir) => format!("{}/{stem}", dir.to_string_lossy()),
        None => stem,
    }
}
