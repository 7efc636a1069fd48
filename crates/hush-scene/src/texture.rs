//! Reading images into linear RGB floats: textures (PNG, JPEG, ... through `image`; EXR through
//! `exr`) and environment maps (EXR).

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use crate::{Texture, TextureId};

/// An image as linear RGB floats, rows top to bottom.
pub(crate) struct Pixels {
    pub width: u32,
    pub height: u32,
    pub data: Vec<f32>,
}

/// sRGB's transfer function, decoded (IEC 61966-2-1).
pub(crate) fn srgb_to_linear(c: f32) -> f32 {
    if c <= 0.04045 { c / 12.92 } else { ((c + 0.055) / 1.055).powf(2.4) }
}

/// Reads an image file. 8- and 16-bit images are sRGB-encoded unless `raw` (Mitsuba's
/// `bitmap` default: `raw = false`) and are converted to linear; EXR and other float images
/// are linear already. Alpha is dropped. Errors name the file.
pub(crate) fn read_image(path: &Path, raw: bool) -> Result<Pixels, String> {
    if let Some(why) = hush_io::describe_unreadable(path) {
        return Err(format!("image file {}: {why}: check the path in the scene file", path.display()));
    }
    let is_exr = path.extension().is_some_and(|e| e.eq_ignore_ascii_case("exr"));
    let pixels = if is_exr {
        read_exr(path)?
    } else {
        let bytes = hush_io::read_limited(path, crate::max_file_bytes(), "image file").map_err(|e| e.to_string())?;
        decode_image(&bytes, &path.display().to_string(), raw)?
    };
    finish(pixels, &path.display().to_string())
}

/// Decodes a PNG or JPEG held in memory (a glTF's embedded image); `label` names it in errors. The
/// declared size is checked against [`MAX_TEXTURE_PIXELS`] before any pixel is decoded.
pub(crate) fn decode_image(bytes: &[u8], label: &str, raw: bool) -> Result<Pixels, String> {
    use image::ImageDecoder;
    let decoder = image::ImageReader::new(std::io::Cursor::new(bytes))
        .with_guessed_format()
        .map_err(|e| format!("cannot read image {label}: {e}"))?
        .into_decoder()
        .map_err(|e| format!("cannot decode image {label}: {e} (hush reads PNG, JPEG and EXR)"))?;
    let (w, h) = decoder.dimensions();
    if u64::from(w) * u64::from(h) > MAX_TEXTURE_PIXELS {
        return Err(format!(
            "image {label}: it declares {w}x{h} pixels, above the limit of {MAX_TEXTURE_PIXELS} for a texture; \
             refused before decoding (resize the image)"
        ));
    }
    let img = image::DynamicImage::from_decoder(decoder)
        .map_err(|e| format!("cannot decode image {label}: {e} (hush reads PNG, JPEG and EXR)"))?;
    let (width, height) = (img.width(), img.height());
    let data = match img.color() {
        image::ColorType::Rgb32F | image::ColorType::Rgba32F => img.to_rgb32f().into_raw(),
        image::ColorType::L8 | image::ColorType::La8 | image::ColorType::Rgb8 | image::ColorType::Rgba8 => {
            let lut: Vec<f32> =
                (0..256).map(|i| if raw { i as f32 / 255.0 } else { srgb_to_linear(i as f32 / 255.0) }).collect();
            img.to_rgb8().into_raw().into_iter().map(|v| lut[v as usize]).collect()
        }
        _ => {
            let mut d = img.to_rgb32f().into_raw();
            if !raw {
                d.iter_mut().for_each(|v| *v = srgb_to_linear(*v));
            }
            d
        }
    };
    Ok(Pixels { width, height, data })
}

/// Checks decoded pixels: finite and not empty.
fn finish(pixels: Pixels, label: &str) -> Result<Pixels, String> {
    if let Some(i) = pixels.data.iter().position(|v| !v.is_finite()) {
        let px = i / 3;
        return Err(format!(
            "image {label} has a non-finite value at pixel ({}, {}): fix the file",
            px % pixels.width as usize,
            px / pixels.width as usize
        ));
    }
    if pixels.width == 0 || pixels.height == 0 {
        return Err(format!("image {label} is empty"));
    }
    Ok(pixels)
}

/// The most pixels of a texture or environment map: 2^28 (a 16384² map is 2^28), as 3 f32 each 3 GiB.
pub(crate) const MAX_TEXTURE_PIXELS: u64 = 1 << 28;

fn read_exr(path: &Path) -> Result<Pixels, String> {
    use exr::prelude::*;
    // The decoder allocates from the header alone: check the declared size before decoding anything.
    let meta = exr::meta::MetaData::read_from_file(path, false)
        .map_err(|e| format!("image {}: reading its EXR header failed: {e}", path.display()))?;
    for header in &meta.headers {
        let (w, h) = (header.layer_size.width() as u64, header.layer_size.height() as u64);
        if w.saturating_mul(h) > MAX_TEXTURE_PIXELS {
            return Err(format!(
                "image {}: its EXR header declares {w}x{h} pixels, above the limit of {MAX_TEXTURE_PIXELS} for a texture \
                 or environment map; refused before decoding (resize the image)",
                path.display()
            ));
        }
    }
    let image = read_first_rgba_layer_from_file(
        path,
        |resolution, _| (resolution.width(), vec![0f32; resolution.width() * resolution.height() * 3]),
        |(w, data), pos, (r, g, b, _a): (f32, f32, f32, f32)| {
            let i = 3 * (pos.y() * *w + pos.x());
            data[i] = r;
            data[i + 1] = g;
            data[i + 2] = b;
        },
    )
    .map_err(|e| format!("cannot read EXR {}: {e} (hush needs R, G and B channels)", path.display()))?;
    let size = image.layer_data.size;
    let (_, data) = image.layer_data.channel_data.pixels;
    Ok(Pixels { width: size.width() as u32, height: size.height() as u32, data })
}

/// Textures of one scene, each file read once.
#[derive(Default)]
pub(crate) struct TextureCache {
    pub textures: Vec<Texture>,
    by_path: HashMap<(PathBuf, bool), TextureId>,
}

impl TextureCache {
    pub fn get(&mut self, path: &Path, raw: bool) -> Result<TextureId, String> {
        let key = (path.to_path_buf(), raw);
        if let Some(&id) = self.by_path.get(&key) {
            return Ok(id);
        }
        let px = read_image(path, raw)?;
        let id = TextureId(self.textures.len() as u32);
        self.textures.push(Texture { path: path.to_path_buf(), width: px.width, height: px.height, data: px.data });
        self.by_path.insert(key, id);
        Ok(id)
    }
}
