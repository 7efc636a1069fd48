//! Open Image Denoise's evaluation transform: exposure, Hable's filmic curve, sRGB.

use hush_dataset::Image;

use crate::{Error, Result};

// Hable's "Uncharted 2" filmic curve with OIDN's constants, from Open Image Denoise's training toolkit,
// `training/color.py` (`tonemap`, RenderKit/oidn commit 951c537): [Hable, 2010, "Uncharted 2: HDR Lighting"].
const A: f64 = 0.22; // shoulder strength
const B: f64 = 0.30; // linear strength
const C: f64 = 0.10; // linear angle
const D: f64 = 0.20; // toe strength
const E: f64 = 0.01; // toe numerator
const F: f64 = 0.30; // toe denominator
const WHITE: f64 = 11.2; // linear white point: maps to 1
const SCALE: f64 = 1.758141; // "exposure bias to match 18% middle gray"

fn hable(x: f64) -> f64 {
    ((x * (A * x + C * B) + D * E) / (x * (A * x + B) + D * F)) - E / F
}

/// OIDN's filmic curve on one linear value (already multiplied by the exposure):
/// `min(1, hable(1.758141·x) / hable(11.2))`, in [0, 1].
///
/// Like OIDN's toolkit, which replaces NaN by 0 and clamps HDR color to ≥ 0 when it loads an image
/// (`training/image.py` `load_image`, `training/dataset.py` `load_image_features`), NaN and negative values
/// map to 0; +Inf maps to 1. Computed in f64 so that huge finite values saturate instead of overflowing.
pub fn filmic(x: f32) -> f32 {
    filmic_f64(x) as f32
}

fn filmic_f64(x: f32) -> f64 {
    if x.is_nan() || x <= 0.0 {
        return 0.0;
    }
    if x.is_infinite() {
        return 1.0;
    }
    (hable(f64::from(x) * SCALE) / hable(WHITE)).clamp(0.0, 1.0)
}

/// sRGB encoding (IEC 61966-2-1, the constants of OIDN's `srgb_forward`), in f64 so that 1 maps to exactly 1.
fn srgb_f64(y: f64) -> f64 {
    if y <= 0.003_130_8 { 12.92 * y } else { 1.055 * y.powf(1.0 / 2.4) - 0.055 }
}

/// The image hush evaluates: `srgb(filmic(exposure × x))` per sample, values in [0, 1]. This is OIDN's
/// `transform_feature(image, 'hdr', 'srgb', exposure)` (`training/dataset.py`), which its `compare_image.py`
/// and `infer.py` apply to both images before PSNR and SSIM. Every channel is mapped the same way.
pub fn tonemap(image: &Image, exposure: f32) -> Image {
    let data = image.data.iter().map(|&v| srgb_f64(filmic_f64(v * exposure)) as f32).collect();
    Image { width: image.width, height: image.height, channels: image.channels, data }
}

/// The exposure hush evaluates at: OIDN's autoexposure of the **reference** (`hush_net::transfer::autoexposure`:
/// 0.18 / geometric mean of the luminance of ≤16×16-pixel bins), so that every method compared against one
/// reference is tonemapped identically, and dark and bright scenes both land mid-range.
///
/// OIDN's own `compare_image.py` uses `--exposure` (default 1) or the `exposure` of a metadata JSON beside
/// the images; hush has no such metadata, and a fixed 1 would make PSNR depend on the scene's brightness.
pub fn exposure_of(reference: &Image) -> Result<f32> {
    if reference.channels != 3 {
        return Err(Error::Shape(format!(
            "exposure_of: the reference must be RGB (3 channels), got a {} image",
            reference.size_string()
        )));
    }
    Ok(hush_net::transfer::autoexposure(&reference.data, reference.width, reference.height))
}
