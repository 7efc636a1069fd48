//! Image quality metrics. Every function takes `(test, reference)`.
//!
//! Conventions (also printed in every report, see [`crate::CONVENTIONS`]):
//! * `psnr`, `ssim`, `mae`, `mse` compare the **tonemapped** images `tonemap(x, exposure_of(reference))`
//!   (OIDN's filmic curve + sRGB, values in [0, 1], see [`crate::tonemap`]); `psnr = 10·log10(1 / mse)`,
//!   +∞ for identical images.
//! * `rel_mse` compares the **linear HDR** images: mean over all samples of `(x − ref)² / (ref² + 0.01)`.
//! * Both images must be RGB of the same size and free of NaN/Inf (the error names the image and pixel).

use candle_core::{Device, Tensor};
use hush_dataset::{Image, check_finite};
use serde::{Deserialize, Serialize};

use crate::{Error, Result, exposure_of, tonemap};

/// All metrics of one `(test, reference)` pair.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Metrics {
    /// dB, on tonemapped images; `f64::INFINITY` when they are identical.
    pub psnr: f64,
    /// Mean SSIM on tonemapped images (hush-net's SSIM: Gaussian 11/1.5, valid, data range 1).
    pub ssim: f64,
    /// Mean absolute error on tonemapped images.
    pub mae: f64,
    /// Mean squared error on tonemapped images.
    pub mse: f64,
    /// Relative MSE on linear HDR images.
    pub rel_mse: f64,
    /// MS-SSIM on tonemapped images (hush-net's MS-SSIM, 5 scales); `None` when the image is too small for
    /// 5 scales (a side below [`MS_SSIM_MIN_SIDE`]), rather than a value on fewer scales that is not comparable.
    pub ms_ssim: Option<f64>,
    /// Mean LDR-FLIP of the tonemapped images ([`crate::flip::flip`] at its default pixels per degree);
    /// `Option` so that rows written before FLIP existed still read.
    pub flip: Option<f64>,
    /// Colour cast: the largest relative difference between a channel's image mean in the test image and in
    /// the reference, on the tonemapped images (`max_c |mean_c(test) / mean_c(ref) − 1|`; 0.01 is a 1 % shift
    /// of one channel). On tonemapped images, as the eye sees them: on linear HDR the means are dominated by
    /// the light sources seen directly, whose radiance no denoiser keeps. `None` where a reference channel's
    /// mean is 0.
    pub color_shift: Option<f64>,
    /// The exposure both images were tonemapped with (from the reference).
    pub exposure: f32,
}

/// [`Metrics::color_shift`] of two images of the same size.
pub fn color_shift(test: &Image, reference: &Image) -> Result<Option<f64>> {
    check_pair(test, reference)?;
    let means = |im: &Image| -> Vec<f64> {
        let mut sum = vec![0.0f64; im.channels];
        for px in im.data.chunks_exact(im.channels) {
            for (s, v) in sum.iter_mut().zip(px) {
                *s += f64::from(*v);
            }
        }
        let n = (im.width * im.height).max(1) as f64;
        sum.into_iter().map(|s| s / n).collect()
    };
    let (t, r) = (means(test), means(reference));
    if r.iter().any(|m| *m <= 0.0) {
        return Ok(None);
    }
    Ok(Some(t.iter().zip(&r).map(|(t, r)| (t / r - 1.0).abs()).fold(0.0, f64::max)))
}

impl Metrics {
    /// The mean of each metric over `all` (the renders of one case, `hush dataset --test-repeats`): PSNR is the
    /// mean of the dB values (+∞ if one is), an optional metric is `None` if one of them is. `None` for none.
    pub fn mean(all: &[Metrics]) -> Option<Metrics> {
        let first = all.first()?;
        let n = all.len() as f64;
        let mean = |f: fn(&Metrics) -> f64| all.iter().map(f).sum::<f64>() / n;
        let mean_opt = |f: fn(&Metrics) -> Option<f64>| {
            all.iter().map(f).collect::<Option<Vec<f64>>>().map(|v| v.iter().sum::<f64>() / n)
        };
        Some(Metrics {
            psnr: mean(|m| m.psnr),
            ssim: mean(|m| m.ssim),
            mae: mean(|m| m.mae),
            mse: mean(|m| m.mse),
            rel_mse: mean(|m| m.rel_mse),
            ms_ssim: mean_opt(|m| m.ms_ssim),
            flip: mean_opt(|m| m.flip),
            color_shift: mean_opt(|m| m.color_shift),
            exposure: first.exposure,
        })
    }
}

/// Computes every metric at once (tonemapping each image once).
pub fn compare(test: &Image, reference: &Image) -> Result<Metrics> {
    check_pair(test, reference)?;
    let exposure = exposure_of(reference)?;
    let (t, r) = (tonemap(test, exposure), tonemap(reference, exposure));
    let mse = mean_by(&t, &r, |d, _| d * d);
    Ok(Metrics {
        psnr: psnr_of_mse(mse),
        ssim: ssim_tonemapped(&t, &r)?,
        mae: mean_by(&t, &r, |d, _| d.abs()),
        mse,
        rel_mse: mean_by(test, reference, rel_se),
        ms_ssim: ms_ssim_tonemapped(&t, &r)?,
        flip: Some(crate::flip::flip(&t, &r)?.mean),
        color_shift: color_shift(&t, &r)?,
        exposure,
    })
}

/// The smallest side for which MS-SSIM is reported: 5 scales of the 11-pixel window, halving 4 times
/// (`hush_net::loss::ms_ssim_scales`). OIDN's toolkit demands a side > 160.
pub const MS_SSIM_MIN_SIDE: usize = hush_net::loss::SSIM_WINDOW << 4;

/// MS-SSIM (5 scales, Wang's weights) of two images already in [0, 1]; `None` if a side is below
/// [`MS_SSIM_MIN_SIDE`].
pub fn ms_ssim_tonemapped(test: &Image, reference: &Image) -> Result<Option<f64>> {
    same_size(test, reference)?;
    let scales = hush_net::loss::MS_SSIM_WEIGHTS.len();
    if hush_net::loss::ms_ssim_scales(test.height, test.width, scales) < scales {
        return Ok(None);
    }
    let (x, y) = (to_nchw(test)?, to_nchw(reference)?);
    let value = hush_net::loss::ms_ssim(&x, &y)?.to_dtype(candle_core::DType::F64)?.to_scalar::<f64>()?;
    Ok(Some(value))
}

/// PSNR in dB of the tonemapped images: `10·log10(1 / mse)`; `f64::INFINITY` if they are identical.
pub fn psnr(test: &Image, reference: &Image) -> Result<f64> {
    Ok(psnr_of_mse(mse(test, reference)?))
}

/// Mean SSIM of the tonemapped images, computed by `hush_net::loss::ssim` (the training loss's code).
pub fn ssim(test: &Image, reference: &Image) -> Result<f64> {
    let (t, r) = tonemapped_pair(test, reference)?;
    ssim_tonemapped(&t, &r)
}

/// Mean absolute error of the tonemapped images.
pub fn mae(test: &Image, reference: &Image) -> Result<f64> {
    let (t, r) = tonemapped_pair(test, reference)?;
    Ok(mean_by(&t, &r, |d, _| d.abs()))
}

/// Mean squared error of the tonemapped images.
pub fn mse(test: &Image, reference: &Image) -> Result<f64> {
    let (t, r) = tonemapped_pair(test, reference)?;
    Ok(mean_by(&t, &r, |d, _| d * d))
}

/// Relative MSE of the linear HDR images: mean of `(x − ref)² / (ref² + 0.01)` over all samples.
pub fn rel_mse(test: &Image, reference: &Image) -> Result<f64> {
    check_pair(test, reference)?;
    Ok(mean_by(test, reference, rel_se))
}

/// `10·log10(1 / mse)` for images in [0, 1]; +∞ for `mse == 0`.
pub fn psnr_of_mse(mse: f64) -> f64 {
    if mse <= 0.0 { f64::INFINITY } else { -10.0 * mse.log10() }
}

/// Mean SSIM of two images already in [0, 1] (no tonemapping), via `hush_net::loss::ssim`.
/// Both must be at least 11×11 (the window); channels are averaged.
pub fn ssim_tonemapped(test: &Image, reference: &Image) -> Result<f64> {
    same_size(test, reference)?;
    let (x, y) = (to_nchw(test)?, to_nchw(reference)?);
    let value = hush_net::loss::ssim(&x, &y)?.to_dtype(candle_core::DType::F64)?.to_scalar::<f64>()?;
    Ok(value)
}

fn rel_se(d: f64, reference: f64) -> f64 {
    d * d / (reference * reference + 1e-2)
}

fn to_nchw(image: &Image) -> Result<Tensor> {
    let t = Tensor::from_slice(&image.data, (image.height, image.width, image.channels), &Device::Cpu)?;
    Ok(t.permute((2, 0, 1))?.unsqueeze(0)?.contiguous()?)
}

fn tonemapped_pair(test: &Image, reference: &Image) -> Result<(Image, Image)> {
    check_pair(test, reference)?;
    let exposure = exposure_of(reference)?;
    Ok((tonemap(test, exposure), tonemap(reference, exposure)))
}

/// Mean over samples of `f(test − reference, reference)`, accumulated in f64.
fn mean_by(test: &Image, reference: &Image, f: impl Fn(f64, f64) -> f64) -> f64 {
    let sum: f64 =
        test.data.iter().zip(&reference.data).map(|(&t, &r)| f(f64::from(t) - f64::from(r), f64::from(r))).sum();
    sum / test.data.len().max(1) as f64
}

fn same_size(test: &Image, reference: &Image) -> Result<()> {
    if (test.width, test.height, test.channels) != (reference.width, reference.height, reference.channels) {
        return Err(Error::Shape(format!(
            "metrics: test image is {} but the reference is {}",
            test.size_string(),
            reference.size_string()
        )));
    }
    Ok(())
}

fn check_pair(test: &Image, reference: &Image) -> Result<()> {
    same_size(test, reference)?;
    if reference.channels != 3 {
        return Err(Error::Shape(format!("metrics: images must be RGB, got {}", reference.size_string())));
    }
    check_finite("test image", test).map_err(Error::NonFinite)?;
    check_finite("reference image", reference).map_err(Error::NonFinite)?;
    Ok(())
}
