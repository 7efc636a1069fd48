//! Open Image Denoise's HDR input pipeline: autoexposure and transfer functions, on plain values and tensors.
//!
//! Constants and formulas follow OIDN's training toolkit (`training/color.py`) and its core library
//! (`core/autoexposure.h`, `core/input_process_kernel.h`). The network sees color as
//! `min(1, transfer(exposure × max(0, color)))`; the inverse undoes it.

use candle_core::{Result, Tensor};
use serde::{Deserialize, Serialize};

/// The largest finite f16 value; the PU and log transfer functions are normalized so that it maps to 1.
pub const HDR_Y_MAX: f32 = 65504.0;

/// Rec.709 luminance with OIDN's coefficients (`training/color.py`, `luminance`).
pub fn luminance(r: f32, g: f32, b: f32) -> f32 {
    0.212671 * r + 0.715160 * g + 0.072169 * b
}

/// OIDN's autoexposure (`core/autoexposure.h` and its CPU kernel): the image is split into
/// `ceil(H/16) × ceil(W/16)` bins of at most 16×16 pixels (bin `i` covers rows `i·H/nb .. (i+1)·H/nb`),
/// each bin's mean luminance is taken, and the result is `0.18 / exp2(mean of log2 L)` over the bins with
/// `L > 1e-8`; 1.0 if there are none. `rgb` is interleaved RGB, `width × height × 3` values.
///
/// Samples that are NaN, infinite or negative count as 0 (OIDN treats NaN and negatives so; for +Inf it
/// returns an exposure that blackens the whole image, which hush does not reproduce).
///
/// OIDN's training toolkit (`training/color.py`) bins slightly differently (`(H + 8) / 16` bins, so bins can
/// be a little larger than 16); this follows the runtime library, which is what denoises users' images.
///
/// # Panics
/// If `rgb.len() != width * height * 3`.
pub fn autoexposure(rgb: &[f32], width: usize, height: usize) -> f32 {
    const MAX_BIN: usize = 16;
    const KEY: f64 = 0.18;
    const EPS: f64 = 1e-8;
    assert_eq!(rgb.len(), width * height * 3, "autoexposure: rgb must hold width * height * 3 values");
    let clean = |v: f32| if v.is_finite() && v > 0.0 { v } else { 0.0 };
    let bins_h = height.div_ceil(MAX_BIN);
    let bins_w = width.div_ceil(MAX_BIN);
    let (mut log_sum, mut count) = (0.0f64, 0usize);
    for i in 0..bins_h {
        let (y0, y1) = (i * height / bins_h, (i + 1) * height / bins_h);
        for j in 0..bins_w {
            let (x0, x1) = (j * width / bins_w, (j + 1) * width / bins_w);
            let mut sum = 0.0f64;
            for y in y0..y1 {
                for x in x0..x1 {
                    let p = &rgb[(y * width + x) * 3..][..3];
                    sum += luminance(clean(p[0]), clean(p[1]), clean(p[2])) as f64;
                }
            }
            let mean = sum / ((y1 - y0) * (x1 - x0)) as f64;
            if mean > EPS {
                log_sum += mean.log2();
                count += 1;
            }
        }
    }
    if count == 0 { 1.0 } else { (KEY / (log_sum / count as f64).exp2()) as f32 }
}

// PU2 fit normalized at 100 cd/m² [Aydin et al., 2008, "Extending Quality Metrics to Full Luminance Range
// Images"], copied from Open Image Denoise's training toolkit, `training/color.py` (PU_A .. PU_X1).
const PU_A: f64 = 1.41283765e+03;
const PU_B: f64 = 1.64593172e+00;
const PU_C: f64 = 4.31384981e-01;
const PU_D: f64 = -2.94139609e-03;
const PU_E: f64 = 1.92653254e-01;
const PU_F: f64 = 6.26026094e-03;
const PU_G: f64 = 9.98620152e-01;
const PU_Y0: f64 = 1.57945760e-06;
const PU_Y1: f64 = 3.22087631e-02;
const PU_X0: f64 = 2.23151711e-03;
const PU_X1: f64 = 3.70974749e-01;
/// `pu_raw(HDR_Y_MAX)`: `PU_E · ln(65504 + PU_F) + PU_G` (checked by a unit test).
const PU_RAW_MAX: f64 = 3.1351190358395673;
/// `ln(HDR_Y_MAX + 1)` (checked by a unit test).
const LOG_RAW_MAX: f64 = 11.08988175458777;

fn pu_raw(y: f64) -> f64 {
    if y <= PU_Y0 {
        PU_A * y
    } else if y <= PU_Y1 {
        PU_B * y.powf(PU_C) + PU_D
    } else {
        PU_E * (y + PU_F).ln() + PU_G
    }
}

fn pu_raw_inverse(x: f64) -> f64 {
    if x <= PU_X0 {
        x / PU_A
    } else if x <= PU_X1 {
        ((x - PU_D) / PU_B).powf(1.0 / PU_C)
    } else {
        ((x - PU_G) / PU_E).exp() - PU_F
    }
}

/// The PU transfer function, normalized so that [`HDR_Y_MAX`] maps to 1 (OIDN's `PUTransferFunction`).
pub fn pu_forward(y: f32) -> f32 {
    (pu_raw(y as f64) / PU_RAW_MAX) as f32
}

/// The inverse of [`pu_forward`].
pub fn pu_inverse(x: f32) -> f32 {
    pu_raw_inverse(x as f64 * PU_RAW_MAX) as f32
}

/// `ln(y + 1) / ln(65505)` (OIDN's `LogTransferFunction`).
pub fn log_forward(y: f32) -> f32 {
    ((y as f64).ln_1p() / LOG_RAW_MAX) as f32
}

/// The inverse of [`log_forward`].
pub fn log_inverse(x: f32) -> f32 {
    (x as f64 * LOG_RAW_MAX).exp_m1() as f32
}

const SRGB_A: f64 = 12.92;
const SRGB_B: f64 = 1.055;
const SRGB_C: f64 = 1.0 / 2.4;
const SRGB_D: f64 = -0.055;
const SRGB_Y0: f64 = 0.0031308;
const SRGB_X0: f64 = 0.04045;

/// The sRGB encoding curve (linear → sRGB), as in OIDN's `srgb_forward`.
pub fn srgb_forward(y: f32) -> f32 {
    srgb_f64(f64::from(y)) as f32
}

/// The sRGB decoding curve (sRGB → linear).
pub fn srgb_inverse(x: f32) -> f32 {
    let x = x as f64;
    (if x <= SRGB_X0 { x / SRGB_A } else { ((x - SRGB_D) / SRGB_B).powf(1.0 / SRGB_C) }) as f32
}

// Hable's "Uncharted 2" filmic curve with OIDN's constants, from Open Image Denoise's training toolkit,
// `training/color.py` (`tonemap`, RenderKit/oidn commit 951c537): [Hable, 2010, "Uncharted 2: HDR Lighting"].
const HABLE_A: f64 = 0.22; // shoulder strength
const HABLE_B: f64 = 0.30; // linear strength
const HABLE_C: f64 = 0.10; // linear angle
const HABLE_D: f64 = 0.20; // toe strength
const HABLE_E: f64 = 0.01; // toe numerator
const HABLE_F: f64 = 0.30; // toe denominator
const FILMIC_WHITE: f64 = 11.2; // linear white point: maps to 1
const FILMIC_SCALE: f64 = 1.758141; // "exposure bias to match 18% middle gray"

/// The exposed linear value that [`display`] shows as white (1): brighter values all look the same.
pub const DISPLAY_WHITE: f32 = (FILMIC_WHITE / FILMIC_SCALE) as f32;

fn hable(x: f64) -> f64 {
    ((x * (HABLE_A * x + HABLE_C * HABLE_B) + HABLE_D * HABLE_E) / (x * (HABLE_A * x + HABLE_B) + HABLE_D * HABLE_F))
        - HABLE_E / HABLE_F
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
    (hable(f64::from(x) * FILMIC_SCALE) / hable(FILMIC_WHITE)).clamp(0.0, 1.0)
}

/// [`srgb_forward`] in f64 (the constants of OIDN's `srgb_forward`), so that 1 maps to exactly 1.
fn srgb_f64(y: f64) -> f64 {
    if y <= SRGB_Y0 { SRGB_A * y } else { SRGB_B * y.powf(SRGB_C) + SRGB_D }
}

/// OIDN's evaluation transform of one exposed linear value, `srgb(filmic(x))`, in [0, 1]: what its
/// `compare_image.py` and hush's metrics apply before PSNR and SSIM (`transform_feature(image, 'hdr', 'srgb',
/// exposure)` in `training/dataset.py`).
pub fn display(x: f32) -> f64 {
    srgb_f64(filmic_f64(x))
}

/// [`display`] on a tensor of exposed linear values, differentiable, for training losses measured where the
/// evaluation measures. Two changes keep a gradient everywhere, where [`display`] is flat: below 0 it continues
/// as the line of its slope at 0 (a negative prediction is pulled up, not ignored), and above the white point
/// the filmic curve is not clamped to 1 (it rises on slowly towards about 1.12, 1.05 after sRGB). Between 0
/// and the white point it is [`display`] up to f32 rounding. Inputs above about 1e18 overflow (`x²`); the
/// loss space feeds it at most the transfer function's [`HDR_Y_MAX`] times the exposure.
pub fn display_tensor(y: &Tensor) -> Result<Tensor> {
    let x = (y.maximum(0.0)? * FILMIC_SCALE)?;
    // hable(x) written without the cancellation of its quotient at large x (where numerator and denominator
    // both grow as A·x²): N / M − E / F = 1 − E / F − ((1 − C)·B·x + D·(F − E)) / M.
    let denominator = ((&x * x.affine(HABLE_A, HABLE_B)?)? + HABLE_D * HABLE_F)?;
    let rest = (x.affine((1.0 - HABLE_C) * HABLE_B, HABLE_D * (HABLE_F - HABLE_E))? / denominator)?;
    let filmic = (rest.affine(-1.0, 1.0 - HABLE_E / HABLE_F)? / hable(FILMIC_WHITE))?;
    let curve = Transfer::Srgb.forward_tensor(&filmic)?;
    // d display / dx at 0: sRGB's linear segment times hable'(0)·scale / hable(white), where
    // hable'(0) = B·(C·F − E) / (D·F²).
    let slope = SRGB_A * HABLE_B * (HABLE_C * HABLE_F - HABLE_E) / (HABLE_D * HABLE_F * HABLE_F) * FILMIC_SCALE
        / hable(FILMIC_WHITE);
    y.lt(0.0)?.where_cond(&(y * slope)?, &curve)
}

/// A transfer function from linear values to what the network sees.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Transfer {
    /// Identity.
    Linear,
    /// sRGB curve, for LDR color.
    Srgb,
    /// Perceptually uniform PU2 fit, OIDN's default for HDR color.
    #[default]
    Pu,
    /// `ln(y+1)/ln(65505)`, OIDN's choice for light maps.
    Log,
}

impl Transfer {
    pub fn forward(self, y: f32) -> f32 {
        match self {
            Transfer::Linear => y,
            Transfer::Srgb => srgb_forward(y),
            Transfer::Pu => pu_forward(y),
            Transfer::Log => log_forward(y),
        }
    }

    pub fn inverse(self, x: f32) -> f32 {
        match self {
            Transfer::Linear => x,
            Transfer::Srgb => srgb_inverse(x),
            Transfer::Pu => pu_inverse(x),
            Transfer::Log => log_inverse(x),
        }
    }

    /// [`Transfer::forward`] element-wise on a tensor of non-negative values (same result as the scalar
    /// version up to f32 rounding; differentiable).
    pub fn forward_tensor(self, y: &Tensor) -> Result<Tensor> {
        match self {
            Transfer::Linear => Ok(y.clone()),
            Transfer::Srgb => {
                let low = (y * SRGB_A)?;
                let high = ((y.maximum(SRGB_Y0)?.powf(SRGB_C)? * SRGB_B)? + SRGB_D)?;
                y.le(SRGB_Y0)?.where_cond(&low, &high)
            }
            Transfer::Pu => {
                let low = (y * PU_A)?;
                let mid = ((y.maximum(PU_Y0)?.powf(PU_C)? * PU_B)? + PU_D)?;
                let high = (((y.maximum(PU_Y1)? + PU_F)?.log()? * PU_E)? + PU_G)?;
                let upper = y.le(PU_Y1)?.where_cond(&mid, &high)?;
                y.le(PU_Y0)?.where_cond(&low, &upper)? / PU_RAW_MAX
            }
            Transfer::Log => (y + 1.0)?.log()? / LOG_RAW_MAX,
        }
    }

    /// [`Transfer::inverse`] element-wise on a tensor.
    pub fn inverse_tensor(self, x: &Tensor) -> Result<Tensor> {
        match self {
            Transfer::Linear => Ok(x.clone()),
            Transfer::Srgb => {
                let low = (x / SRGB_A)?;
                let high = ((x.maximum(SRGB_X0)? - SRGB_D)? / SRGB_B)?.powf(1.0 / SRGB_C)?;
                x.le(SRGB_X0)?.where_cond(&low, &high)
            }
            Transfer::Pu => {
                let x = (x * PU_RAW_MAX)?;
                let low = (&x / PU_A)?;
                let mid = ((x.maximum(PU_X0)? - PU_D)? / PU_B)?.powf(1.0 / PU_C)?;
                let high = (((x.maximum(PU_X1)? - PU_G)? / PU_E)?.exp()? - PU_F)?;
                let upper = x.le(PU_X1)?.where_cond(&mid, &high)?;
                x.le(PU_X0)?.where_cond(&low, &upper)
            }
            Transfer::Log => (x * LOG_RAW_MAX)?.exp()? - 1.0,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normalization_constants_match_their_formulas() {
        assert_eq!(PU_RAW_MAX, PU_E * (HDR_Y_MAX as f64 + PU_F).ln() + PU_G);
        assert_eq!(LOG_RAW_MAX, (HDR_Y_MAX as f64 + 1.0).ln());
    }
}
