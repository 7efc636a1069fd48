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
    let n = width * height * 3;
    if out.len() != n || color.len() != n || variance.len() != n {
        candle_core::bail!(
            "keep_exact_pixels: a {width}x{height} RGB image has {n} values; got output {}, color {}, variance {}",
            out.len(),
            color.len(),
            variance.len()
        )
    }
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
