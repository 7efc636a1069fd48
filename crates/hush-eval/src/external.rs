//! Python baselines run as an external process: BM3D (PyPI `bm3d` 4.0.3) and official Open Image Denoise
//! 2.5.1 (PyPI `pyoidn`), installed by `cargo xtask baselines setup` into `target/baselines-venv`.
//!
//! [`run_baseline`] writes every input as a float32 `.npy` (H×W×3) into a fresh temporary directory with a
//! `job.json`, runs the venv's Python on the runner script (`baselines/run_baseline.py`, compiled into this
//! crate and written beside the job), and reads the outputs and the runner's own timing back: each image is
//! denoised once to warm up, then `repeats` times, and the median is reported, so Python's start-up and
//! imports are not counted. When the venv or a package is missing the outcome is
//! [`Outcome::Skipped`] with the install command, never an error.
//!
//! - **BM3D** works on the tonemapped image: `tonemap(color, exposure_of(color))` (the noisy image's own
//!   autoexposure: no reference is used), σ chosen by [`bm3d_sigma`], and the output is mapped back to linear
//!   by inverting that tonemap ([`inverse_tonemap`]; values that tonemap to 1 come back as the curve's white
//!   point).
//! - **OIDN** gets the linear HDR color with albedo and normal when both are given (`hdr=True`, quality
//!   `balanced`: the weights `rt_hdr_alb_nrm`), else the color alone (`rt_hdr`).

use std::path::{Path, PathBuf};
use std::process::Command;

use hush_dataset::{Image, check_finite, write_atomic};

use crate::guided::noise_sigma_mad;
use crate::{Error, Result, exposure_of, filmic, tonemap};

/// The command that installs the baselines.
pub const INSTALL: &str = "cargo xtask baselines setup";

/// The runner script, written next to each job.
const RUNNER: &str = include_str!("../baselines/run_baseline.py");

/// Exit code of the runner when a Python package is missing.
const EXIT_MISSING: i32 = 3;

/// BM3D's σ is this multiple of the robust noise estimate ([`bm3d_sigma`]).
pub const BM3D_SIGMA_FACTOR: f32 = 5.0;

/// A Python baseline.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Baseline {
    /// BM3D on the tonemapped image (`bm3d.bm3d_rgb`).
    Bm3d,
    /// Official OIDN 2.5.1 through `pyoidn.denoise`.
    Oidn,
}

impl Baseline {
    /// The name used in reports and in `job.json`.
    pub fn name(self) -> &'static str {
        match self {
            Baseline::Bm3d => "bm3d",
            Baseline::Oidn => "oidn",
        }
    }
}

/// One image to denoise: linear HDR color and optional albedo and normal of the same size.
#[derive(Clone, Copy, Debug)]
pub struct Input<'a> {
    pub color: &'a Image,
    pub albedo: Option<&'a Image>,
    pub normal: Option<&'a Image>,
}

/// The result of [`run_baseline`].
#[derive(Clone, Debug)]
pub enum Outcome {
    /// Denoised linear images (one per input, same order) and the warm median seconds per image.
    Done { images: Vec<Image>, seconds: Vec<f64>, versions: serde_json::Value },
    /// The baseline is not installed: why, and the command that installs it.
    Skipped { reason: String, install: &'static str },
}

/// The Python of the baselines venv: `$HUSH_BASELINES_PYTHON` if set, else
/// `$CARGO_TARGET_DIR/baselines-venv/bin/python`, else `<workspace>/target/baselines-venv/bin/python`.
/// The path may not exist ([`run_baseline`] then skips).
pub fn venv_python() -> PathBuf {
    if let Some(p) = std::env::var_os("HUSH_BASELINES_PYTHON") {
        return PathBuf::from(p);
    }
    let target = std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../../target"));
    target.join("baselines-venv").join("bin").join("python")
}

/// BM3D's σ for one tonemapped image (values in [0, 1]): [`BM3D_SIGMA_FACTOR`] × the mean over channels of
/// the robust MAD noise estimate ([`noise_sigma_mad`]). BM3D at an estimated σ under-smooths Monte-Carlo
/// noise, which is heavy-tailed and uneven: the MAD estimate sits below the noise's standard deviation (1.8×
/// below on the Cornell box at 16 spp). The factor was set once on that image (Mitsuba, 512², scored against
/// its 1792-spp render on the tonemapped image: noisy 25.6 dB; factor 2: 28.9, 3: 32.9, 4: 37.0, 5: 37.7,
/// 6: 37.6, 8: 37.3 dB), i.e. 2.8× the oracle σ, and uses no reference at run time.
pub fn bm3d_sigma(tonemapped: &Image) -> f32 {
    let (w, h, c) = (tonemapped.width, tonemapped.height, tonemapped.channels);
    let per_channel: f32 = (0..c)
        .map(|ch| {
            let plane: Vec<f32> = tonemapped.data.iter().skip(ch).step_by(c).copied().collect();
            noise_sigma_mad(&plane, w, h)
        })
        .sum::<f32>()
        / c.max(1) as f32;
    BM3D_SIGMA_FACTOR * per_channel
}

/// Inverse of [`tonemap`] at `exposure`: sRGB decode, then the filmic curve inverted by bisection (it is
/// monotonic), then ÷ exposure. Values ≥ 1 map to the curve's white point (the smallest input that maps to 1).
pub fn inverse_tonemap(image: &Image, exposure: f32) -> Image {
    let white = {
        let (mut lo, mut hi) = (0.0f32, 64.0f32);
        for _ in 0..60 {
            let mid = 0.5 * (lo + hi);
            if filmic(mid) >= 1.0 { hi = mid } else { lo = mid }
        }
        hi
    };
    let invert = |s: f32| -> f32 {
        let y = if s <= 0.04045 { s / 12.92 } else { ((s + 0.055) / 1.055).powf(2.4) };
        if y <= 0.0 {
            return 0.0;
        }
        let (mut lo, mut hi) = (0.0f32, white);
        for _ in 0..40 {
            let mid = 0.5 * (lo + hi);
            if filmic(mid) < y { lo = mid } else { hi = mid }
        }
        0.5 * (lo + hi) / exposure
    };
    Image {
        width: image.width,
        height: image.height,
        channels: image.channels,
        data: image.data.iter().map(|&v| invert(v)).collect(),
    }
}

/// Runs `baseline` on every input with the Python at `python` ([`venv_python`]); `repeats` ≥ 1 timed runs per
/// image after one warm-up. Errors only on bad input (size, channels, NaN/Inf, naming the image) and on a
/// runner that fails for another reason than a missing package (its output is in the message).
pub fn run_baseline(baseline: Baseline, inputs: &[Input], python: &Path, repeats: usize) -> Result<Outcome> {
    run_baseline_with(baseline, inputs, python, repeats, None)
}

/// [`run_baseline`] of [`Baseline::Oidn`] with other weights than OIDN's built-in ones: a TZA archive (OIDN's
/// official weights, or a hush model written by `hush export`), which OIDN's runtime loads through its
/// `weights` filter parameter (`oidnSetSharedFilterData`), as `oidnDenoise -w` does.
pub fn run_oidn_with_weights(inputs: &[Input], weights: &[u8], python: &Path, repeats: usize) -> Result<Outcome> {
    run_baseline_with(Baseline::Oidn, inputs, python, repeats, Some(weights))
}

fn run_baseline_with(
    baseline: Baseline,
    inputs: &[Input],
    python: &Path,
    repeats: usize,
    weights: Option<&[u8]>,
) -> Result<Outcome> {
    for (i, input) in inputs.iter().enumerate() {
        check_input(i, input)?;
    }
    if inputs.is_empty() {
        return Ok(Outcome::Done { images: vec![], seconds: vec![], versions: serde_json::Value::Null });
    }
    if !python.is_file() {
        return Ok(Outcome::Skipped {
            reason: format!(
                "{}: the baselines venv is not installed ({} not found)",
                baseline.name(),
                crate::shown_path(python)
            ),
            install: INSTALL,
        });
    }
    let dir = JobDir::new(baseline)?;
    let mut items = Vec::new();
    let mut exposures = Vec::new();
    for (i, input) in inputs.iter().enumerate() {
        let color_name = format!("color_{i:04}.npy");
        let mut item = serde_json::json!({ "color": color_name, "out": format!("out_{i:04}.npy") });
        match baseline {
            Baseline::Bm3d => {
                let exposure = exposure_of(input.color)?;
                let t = tonemap(input.color, exposure);
                item["sigma"] = serde_json::json!(bm3d_sigma(&t));
                write_npy(&dir.0.join(&color_name), &t)?;
                exposures.push(exposure);
            }
            Baseline::Oidn => {
                write_npy(&dir.0.join(&color_name), input.color)?;
                if let (Some(a), Some(n)) = (input.albedo, input.normal) {
                    let (an, nn) = (format!("albedo_{i:04}.npy"), format!("normal_{i:04}.npy"));
                    write_npy(&dir.0.join(&an), a)?;
                    write_npy(&dir.0.join(&nn), n)?;
                    item["albedo"] = serde_json::json!(an);
                    item["normal"] = serde_json::json!(nn);
                }
            }
        }
        items.push(item);
    }
    let mut job = serde_json::json!({ "method": baseline.name(), "repeats": repeats.max(1), "items": items });
    if let Some(bytes) = weights {
        write_file(&dir.0.join("weights.tza"), bytes)?;
        job["weights"] = serde_json::json!("weights.tza");
    }
    write_file(&dir.0.join("job.json"), serde_json::to_string_pretty(&job).expect("JSON values serialize").as_bytes())?;
    let script = dir.0.join("run_baseline.py");
    write_file(&script, RUNNER.as_bytes())?;

    let output = Command::new(python).arg(&script).arg(&dir.0).output().map_err(|e| Error::File {
        path: python.to_path_buf(),
        action: "start the baselines' Python",
        source: e,
    })?;
    let result_path = dir.0.join("result.json");
    let result: Option<serde_json::Value> =
        std::fs::read_to_string(&result_path).ok().and_then(|t| serde_json::from_str(&t).ok());
    if output.status.code() == Some(EXIT_MISSING) {
        let missing = result.as_ref().and_then(|r| r["missing"].as_str()).unwrap_or("a package").to_string();
        return Ok(Outcome::Skipped {
            reason: format!(
                "{}: the Python package `{missing}` is not installed in {}",
                baseline.name(),
                crate::shown_path(python)
            ),
            install: INSTALL,
        });
    }
    if !output.status.success() {
        return Err(Error::Io(std::io::Error::other(format!(
            "{} baseline: `{} {} {}` failed ({}):\n{}",
            baseline.name(),
            python.display(),
            script.display(),
            dir.0.display(),
            output.status,
            String::from_utf8_lossy(&output.stderr).trim_end()
        ))));
    }
    let result = result.ok_or_else(|| {
        Error::Io(std::io::Error::other(format!(
            "{}: missing or invalid after the runner succeeded",
            result_path.display()
        )))
    })?;
    let seconds: Vec<f64> =
        result["seconds"].as_array().map(|a| a.iter().filter_map(|v| v.as_f64()).collect()).unwrap_or_default();
    if seconds.len() != inputs.len() {
        return Err(Error::Io(std::io::Error::other(format!(
            "{}: expected {} timings, got {}",
            result_path.display(),
            inputs.len(),
            seconds.len()
        ))));
    }
    let mut images = Vec::with_capacity(inputs.len());
    for (i, input) in inputs.iter().enumerate() {
        let path = dir.0.join(format!("out_{i:04}.npy"));
        let out = read_npy(&path)?;
        if (out.width, out.height, out.channels) != (input.color.width, input.color.height, 3) {
            return Err(Error::Shape(format!(
                "{}: the runner wrote {} for a {} input",
                path.display(),
                out.size_string(),
                input.color.size_string()
            )));
        }
        images.push(match baseline {
            Baseline::Bm3d => inverse_tonemap(&out, exposures[i]),
            Baseline::Oidn => out,
        });
    }
    Ok(Outcome::Done { images, seconds, versions: result["versions"].clone() })
}

fn check_input(i: usize, input: &Input) -> Result<()> {
    let c = input.color;
    for (what, image) in [("color", Some(c)), ("albedo", input.albedo), ("normal", input.normal)] {
        let Some(image) = image else { continue };
        if image.channels != 3 || (image.width, image.height) != (c.width, c.height) || c.width == 0 || c.height == 0 {
            return Err(Error::Shape(format!(
                "external baseline: input {i}: the {what} image is {} but the color is {} (need RGB, same size)",
                image.size_string(),
                c.size_string()
            )));
        }
        check_finite(format!("external baseline input {i} {what}"), image).map_err(Error::NonFinite)?;
    }
    Ok(())
}

/// A fresh temporary directory, removed when dropped.
struct JobDir(PathBuf);

impl JobDir {
    fn new(baseline: Baseline) -> Result<JobDir> {
        use std::sync::atomic::{AtomicUsize, Ordering};
        static COUNTER: AtomicUsize = AtomicUsize::new(0);
        let n = COUNTER.fetch_add(1, Ordering::Relaxed);
        let dir = std::env::temp_dir().join(format!("hush-baseline-{}-{}-{n}", baseline.name(), std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).map_err(|e| Error::File { path: dir.clone(), action: "create", source: e })?;
        Ok(JobDir(dir))
    }
}

impl Drop for JobDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

fn write_file(path: &Path, bytes: &[u8]) -> Result<()> {
    std::fs::write(path, bytes).map_err(|e| Error::File { path: path.to_path_buf(), action: "write", source: e })
}

/// Writes an image as a NumPy `.npy` file: little-endian float32, C order, shape (height, width, channels),
/// atomically (temp + rename).
pub fn write_npy(path: &Path, image: &Image) -> Result<()> {
    let mut header = format!(
        "{{'descr': '<f4', 'fortran_order': False, 'shape': ({}, {}, {}), }}",
        image.height, image.width, image.channels
    );
    // Magic (6) + version (2) + header length (2) + header, padded with spaces to a multiple of 64, ending in '\n'.
    let total = (10 + header.len() + 1).div_ceil(64) * 64;
    header.push_str(&" ".repeat(total - 10 - header.len() - 1));
    header.push('\n');
    let mut bytes = Vec::with_capacity(total + image.data.len() * 4);
    bytes.extend_from_slice(b"\x93NUMPY\x01\x00");
    bytes.extend_from_slice(&(header.len() as u16).to_le_bytes());
    bytes.extend_from_slice(header.as_bytes());
    for v in &image.data {
        bytes.extend_from_slice(&v.to_le_bytes());
    }
    write_atomic(path, |tmp| std::fs::write(tmp, &bytes)).map_err(|e| Error::File {
        path: path.to_path_buf(),
        action: "write",
        source: e,
    })
}

/// Reads a NumPy `.npy` file of little-endian float32 in C order with shape (height, width) or
/// (height, width, channels) as an [`Image`]. Errors name the file and what is wrong.
pub fn read_npy(path: &Path) -> Result<Image> {
    let bytes = std::fs::read(path).map_err(|e| Error::File { path: path.to_path_buf(), action: "read", source: e })?;
    let bad = |why: String| Error::Shape(format!("{}: not a float32 .npy image: {why}", path.display()));
    if bytes.len() < 10 || &bytes[..6] != b"\x93NUMPY" {
        return Err(bad("missing the \\x93NUMPY magic".into()));
    }
    let (header_len, start) = match bytes[6] {
        1 => (u16::from_le_bytes([bytes[8], bytes[9]]) as usize, 10),
        2 | 3 if bytes.len() >= 12 => (u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize, 12),
        v => return Err(bad(format!("unsupported format version {v}"))),
    };
    let header = bytes.get(start..start + header_len).ok_or_else(|| bad("truncated header".into()))?;
    let header = String::from_utf8_lossy(header);
    if !header.contains("'descr': '<f4'") {
        return Err(bad(format!("dtype is not little-endian float32 (header {header:?})")));
    }
    if header.contains("'fortran_order': True") {
        return Err(bad("Fortran order is not supported".into()));
    }
    let shape_text = header
        .split("'shape':")
        .nth(1)
        .and_then(|s| s.split('(').nth(1))
        .and_then(|s| s.split(')').next())
        .ok_or_else(|| bad(format!("no shape in header {header:?}")))?;
    let dims: Vec<usize> = shape_text
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| s.parse::<usize>().map_err(|_| bad(format!("bad shape {shape_text:?}"))))
        .collect::<Result<_>>()?;
    let (h, w, c) = match dims[..] {
        [h, w] => (h, w, 1),
        [h, w, c] => (h, w, c),
        _ => return Err(bad(format!("shape {dims:?} is not (height, width[, channels])"))),
    };
    let data_bytes = &bytes[start + header_len..];
    if data_bytes.len() != h * w * c * 4 {
        return Err(bad(format!("{} data bytes for shape {dims:?}", data_bytes.len())));
    }
    let data = data_bytes.chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect();
    Image::new(w, h, c, data).map_err(Error::Dataset)
}
