//! The whole inference path on one image, as OIDN's runtime runs it: autoexposure, input processing, the
//! network on the zero-padded image, output processing.

use candle_core::Result;

use crate::input::{build_inference_input, finish_color_in_place};
use crate::net::DenoiseNet;
use crate::transfer::autoexposure;
use crate::weights::ModelInfo;

/// Denoises linear HDR `color` (interleaved RGB, `width × height × 3`) with the auxiliary images of
/// `info.features` (same layout, same order), on the device of `net`'s weights.
///
/// OIDN's `UNetFilter` with `hdr = true` and `inputScale` unset: exposure = [`autoexposure`] of the color;
/// the input as [`build_inference_input`] builds it (no ≤ 1 clamp); the image at the top left of a zero
/// tile padded to a multiple of 16 ([`UNet::forward_padded`](crate::UNet::forward_padded); the patch MLP
/// pads itself); the output clamped ≥ 0, inverse transfer, ÷ exposure ([`crate::finish_color`]). Returns
/// interleaved RGB.
pub fn denoise(
    net: &impl DenoiseNet,
    info: &ModelInfo,
    width: usize,
    height: usize,
    color: &[f32],
    aux: &[&[f32]],
) -> Result<Vec<f32>> {
    if net.net_config() != info.net {
        candle_core::bail!("denoise: the network is {:?} but the model info describes {:?}", net.net_config(), info.net)
    }
    if color.len() != width * height * 3 {
        candle_core::bail!(
            "denoise: color has {} values, a {width}x{height} RGB image needs {}",
            color.len(),
            width * height * 3
        )
    }
    let exposure = autoexposure(color, width, height);
    let input = build_inference_input(&info.features, width, height, color, aux, exposure, info.transfer)?;
    let mut y = net.forward_hwc(input, width, height, info.features.in_channels())?;
    finish_color_in_place(&mut y, exposure, info.transfer);
    Ok(y)
}

/// Where a render's every sample agreed, its pixel is already exact: a camera ray that saw a constant sky or
/// an emitter directly returns the same radiance on every sample, so the pixel's sample variance is exactly 0
/// (the tracer's merged sums cancel exactly for equal samples). A network reproduces such pixels only
/// approximately (it smooths a constant sky by a few thousandths, which FLIP sees over the whole sky); this
/// writes the noisy value back into `out` for every pixel that, with each of its 8 neighbours inside the image,
/// has variance 0 in every channel and a positive, finite color. Neighbours too, so that a pixel on an emitter's
/// edge whose few samples all happened to land inside it is left to the network; black pixels too, since paths
/// that all found no light say nothing about what more paths would find.
///
/// `color`, `variance` (per channel, of the pixel's mean: `hush render`'s `variance` layer) and `out` are
/// interleaved RGB, `width × height × 3` values. One sample per pixel has no variance estimate (the tracer
/// writes 0): where no pixel has a variance above 0, nothing is kept. Returns how many pixels were kept.
pub fn keep_exact_pixels(
    out: &mut [f32],
    color: &[f32],
    variance: &[f32],
    width: usize,
    height: usize,
) -> Result<usize> {
    check_sizes("keep_exact_pixels", [out.len(), color.len(), variance.len()], width, height)?;
    if !variance.iter().any(|&v| v > 0.0) {
        return Ok(0);
    }
    let exact: Vec<bool> = color
        .chunks_exact(3)
        .zip(variance.chunks_exact(3))
        .map(|(c, v)| {
            v.iter().all(|&v| v == 0.0) && c.iter().all(|&c| c.is_finite() && c >= 0.0) && c.iter().sum::<f32>() > 0.0
        })
        .collect();
    let mut kept = 0;
    for y in 0..height {
        for x in 0..width {
            let rows = y.saturating_sub(1)..=(y + 1).min(height - 1);
            let all =
                rows.into_iter().all(|r| (x.saturating_sub(1)..=(x + 1).min(width - 1)).all(|c| exact[r * width + c]));
            if all {
                let p = (y * width + x) * 3;
                out[p..p + 3].copy_from_slice(&color[p..p + 3]);
                kept += 1;
            }
        }
    }
    Ok(kept)
}

/// Fails unless the output, color and variance (`lens`) are each `width × height × 3` values.
fn check_sizes(what: &str, lens: [usize; 3], width: usize, height: usize) -> Result<()> {
    let n = width * height * 3;
    if lens.iter().any(|&l| l != n) {
        candle_core::bail!(
            "{what}: a {width}x{height} RGB image has {n} values; got output {}, color {}, variance {}",
            lens[0],
            lens[1],
            lens[2]
        )
    }
    Ok(())
}

/// Where the render is nearly converged, its own pixel is worth as much as the network's: mixes the noisy input
/// back into the denoised `out` by each pixel's standard error. With `s²` the pixel's variance of its mean
/// (averaged over the channels and over the `(2·radius+1)²` window around it, clipped to the image, so that a
/// few samples that happened to agree do not pass for converged) and `L` the denoised pixel's mean value,
/// the network is taken to err by `tau·L` (a relative error, chosen on validation scenes) and the two
/// estimates are combined as independent ones are: the input's weight is `tau²L² / (tau²L² + s²)`, near 1
/// where the render's relative standard error is far below `tau`, near 0 where it is far above. A pixel
/// with `s² = 0` (every sample in its window agreed: [`keep_exact_pixels`]'s case) or a non-positive or
/// non-finite color or output is left as the network made it.
///
/// Same layouts as [`keep_exact_pixels`]; where no pixel has a variance above 0 (one sample per pixel),
/// nothing changes. Returns the mean input weight over the image.
pub fn blend_input(
    out: &mut [f32],
    color: &[f32],
    variance: &[f32],
    width: usize,
    height: usize,
    tau: f32,
    radius: usize,
) -> Result<f32> {
    check_sizes("blend_input", [out.len(), color.len(), variance.len()], width, height)?;
    if !(tau.is_finite() && tau > 0.0) {
        candle_core::bail!("blend_input: the network's relative error must be positive and finite, got {tau}")
    }
    if !variance.iter().any(|&v| v > 0.0) {
        return Ok(0.0);
    }
    // The channel-mean variance, then its window mean by a summed-area table (f64: sums of many small terms).
    let pixel_var: Vec<f64> = variance
        .chunks_exact(3)
        .map(|v| v.iter().map(|&v| if v.is_finite() { v.max(0.0) as f64 } else { 0.0 }).sum::<f64>() / 3.0)
        .collect();
    let mut table = vec![0.0f64; (width + 1) * (height + 1)];
    for y in 0..height {
        let mut row = 0.0;
        for x in 0..width {
            row += pixel_var[y * width + x];
            table[(y + 1) * (width + 1) + x + 1] = table[y * (width + 1) + x + 1] + row;
        }
    }
    let tau2 = (tau as f64) * (tau as f64);
    let mut total_weight = 0.0f64;
    for y in 0..height {
        let (y0, y1) = (y.saturating_sub(radius), (y + radius + 1).min(height));
        for x in 0..width {
            let (x0, x1) = (x.saturating_sub(radius), (x + radius + 1).min(width));
            let sum = table[y1 * (width + 1) + x1] - table[y0 * (width + 1) + x1] - table[y1 * (width + 1) + x0]
                + table[y0 * (width + 1) + x0];
            let s2 = sum / ((y1 - y0) * (x1 - x0)) as f64;
            let p = (y * width + x) * 3;
            let (c, o) = (&color[p..p + 3], &out[p..p + 3]);
            let level = o.iter().map(|&v| v as f64).sum::<f64>() / 3.0;
            if s2 <= 0.0 || !(level > 0.0 && level.is_finite()) || !c.iter().all(|v| v.is_finite() && *v >= 0.0) {
                continue;
            }
            let a = tau2 * level * level;
            let w = a / (a + s2);
            for k in p..p + 3 {
                out[k] += (w * (color[k] - out[k]) as f64) as f32;
            }
            total_weight += w;
        }
    }
    Ok((total_weight / (width * height) as f64) as f32)
}
