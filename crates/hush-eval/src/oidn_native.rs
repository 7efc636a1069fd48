//! Official Open Image Denoise 2.5.1 in process, through the `oidn` crate (cargo feature `oidn`), so that its
//! timing has no process or Python overhead. Built against the library bundled in PyPI's `pyoidn` 2.5.1.0
//! (installed by `cargo xtask baselines setup`):
//!
//! ```sh
//! export OIDN_DIR=target/baselines-venv/lib/python3.*/site-packages/pyoidn/oidn
//! LD_LIBRARY_PATH=$OIDN_DIR/lib cargo test -p hush-eval --features oidn --test it oidn_native
//! ```
//!
//! Same settings as the Python runner (`external`): filter `RT`, `hdr`, quality `balanced`, albedo and
//! normal when both are given (weights `rt_hdr_alb_nrm`), else color only (`rt_hdr`).

use hush_dataset::{Image, check_finite};

use crate::{Error, Result};

/// Denoises `color` (linear HDR RGB) with optional albedo and normal; `repeats` ≥ 1 timed runs after one
/// warm-up. Returns the output and the median seconds of the timed runs. Errors name the bad input or carry
/// OIDN's message.
pub fn denoise(color: &Image, albedo: Option<&Image>, normal: Option<&Image>, repeats: usize) -> Result<(Image, f64)> {
    for (what, image) in [("color", Some(color)), ("albedo", albedo), ("normal", normal)] {
        let Some(image) = image else { continue };
        if image.channels != 3 || (image.width, image.height) != (color.width, color.height) {
            return Err(Error::Shape(format!(
                "OIDN: the {what} image is {} but the color is {} (need RGB, same size)",
                image.size_string(),
                color.size_string()
            )));
        }
        check_finite(format!("OIDN {what} image"), image).map_err(Error::NonFinite)?;
    }
    let oidn_err = |e: oidn::Error| Error::Io(std::io::Error::other(format!("Open Image Denoise: {e}")));
    let device = oidn::Device::cpu().map_err(oidn_err)?;
    let mut filter = oidn::RayTracing::try_new(&device).map_err(oidn_err)?;
    filter.hdr(true).filter_quality(oidn::Quality::Balanced).image_dimensions(color.width, color.height);
    if let (Some(a), Some(n)) = (albedo, normal) {
        filter.albedo_normal(&a.data, &n.data);
    }
    let mut output = vec![0.0f32; color.data.len()];
    filter.filter(&color.data, &mut output).map_err(oidn_err)?;
    let mut failure = None;
    let timing = crate::time_median(repeats, 0, || {
        if let Err(e) = filter.filter(&color.data, &mut output) {
            failure.get_or_insert(e);
        }
    });
    if let Some(e) = failure {
        return Err(oidn_err(e));
    }
    device.get_error().map_err(oidn_err)?;
    Ok((Image { width: color.width, height: color.height, channels: 3, data: output }, timing.median))
}
