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
