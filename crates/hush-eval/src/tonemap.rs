//! Open Image Denoise's evaluation transform: exposure, Hable's filmic curve, sRGB.

use hush_dataset::Image;

use crate::{Error, Result};

pub use hush_net::transfer::filmic;

/// The image hush evaluates: `srgb(filmic(exposure × x))` per sample, values in [0, 1]. This is OIDN's
/// `transform_feature(image, 'hdr', 'srgb', exposure)` (`training/dataset.py`), which its `compare_image.py`
/// and `infer.py` apply to both images before PSNR and SSIM. Every channel is mapped the same way.
pub fn tonemap(image: &Image, exposure: f32) -> Image {
    let data = image.data.iter().map(|&v| hush_net::transfer::display(v * exposure) as f32).collect();
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
