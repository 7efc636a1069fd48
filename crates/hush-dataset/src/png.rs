//! 8-bit sRGB PNG previews of linear images.

use std::path::Path;

use crate::{Error, Image, Result, write_atomic};

/// The sRGB encoding of a linear value in [0, 1] (IEC 61966-2-1).
pub fn srgb_encode(linear: f32) -> f32 {
    if linear <= 0.003_130_8 { 12.92 * linear } else { 1.055 * linear.powf(1.0 / 2.4) - 0.055 }
}

/// Writes `image × exposure`, clamped to [0, 1] and sRGB-encoded, as an 8-bit RGB PNG (atomically).
/// 1-channel images are written as grey; of more than 3 channels only the first 3 are used.
/// NaN is written as 0. This is a preview, not a tonemapped evaluation image (see hush-eval for that).
pub fn write_png_preview(path: impl AsRef<Path>, image: &Image, exposure: f32) -> Result<()> {
    let path = path.as_ref();
    if image.channels != 1 && image.channels < 3 {
        return Err(Error::Shape(format!(
            "{}: a PNG preview needs 1 or at least 3 channels, got a {} image",
            path.display(),
            image.size_string()
        )));
    }
    let to_u8 = |v: f32| {
        let v = (v * exposure).clamp(0.0, 1.0); // clamp maps NaN to NaN; the `as` cast below maps it to 0
        (srgb_encode(v) * 255.0 + 0.5) as u8
    };
    let mut bytes = Vec::with_capacity(image.width * image.height * 3);
    for p in image.data.chunks_exact(image.channels) {
        if image.channels == 1 {
            bytes.extend_from_slice(&[to_u8(p[0]); 3]);
        } else {
            bytes.extend(p[..3].iter().map(|&v| to_u8(v)));
        }
    }
    let (w, h) = (dim(path, image.width)?, dim(path, image.height)?);
    write_atomic(path, |tmp| {
        image::save_buffer_with_format(tmp, &bytes, w, h, image::ExtendedColorType::Rgb8, image::ImageFormat::Png)
            .map_err(|source| Error::Png { path: path.to_path_buf(), source })
    })
}

fn dim(path: &Path, n: usize) -> Result<u32> {
    u32::try_from(n).map_err(|_| Error::Shape(format!("{}: image side {n} is too large for PNG", path.display())))
}
