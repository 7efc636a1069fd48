//! Portable float maps (PFM), the format of Open Image Denoise's command-line tools: a text header
//! (`PF` for RGB or `Pf` for one channel, `width height`, a scale whose sign gives the byte order) and
//! the rows of f32 samples from the bottom up.

use std::path::Path;

use crate::{Error, Image, Result, write_atomic};

fn bad(path: &Path, what: String) -> Error {
    Error::Shape(format!("{}: not a PFM image: {what}", path.display()))
}

/// Reads an RGB (`PF`) or one-channel (`Pf`) PFM file, rows top first. Only a regular file is read, and at
/// most the bytes [`crate::max_exr_samples`] samples need (the limit every image reader of hush shares): a
/// device, a pipe or an oversized file is refused, not read until memory runs out.
pub fn read_pfm(path: impl AsRef<Path>) -> Result<Image> {
    use std::io::Read as _;
    let path = path.as_ref();
    let io = |source| Error::File { path: path.into(), action: "read", source };
    let meta = std::fs::metadata(path).map_err(io)?;
    if !meta.is_file() {
        return Err(bad(path, "it is not a regular file (a directory, a device or a pipe)".into()));
    }
    let max_samples = crate::max_exr_samples();
    let limit = max_samples.saturating_mul(4).saturating_add(4096);
    let mut bytes = Vec::new();
    std::fs::File::open(path).and_then(|f| f.take(limit + 1).read_to_end(&mut bytes)).map_err(io)?;
    if bytes.len() as u64 > limit {
        return Err(bad(
            path,
            format!(
                "it is larger than {limit} bytes, the most that {max_samples} samples need (HUSH_MAX_EXR_SAMPLES raises it)"
            ),
        ));
    }
    // Three whitespace-separated header tokens after the magic, then exactly one whitespace byte.
    let mut pos = 0;
    let mut token = || -> Result<String> {
        while bytes.get(pos).is_some_and(u8::is_ascii_whitespace) {
            pos += 1;
        }
        let start = pos;
        while bytes.get(pos).is_some_and(|b| !b.is_ascii_whitespace()) {
            pos += 1;
        }
        if start == pos {
            return Err(bad(path, "the header ends early".into()));
        }
        Ok(String::from_utf8_lossy(&bytes[start..pos]).into_owned())
    };
    let channels = match token()?.as_str() {
        "PF" => 3,
        "Pf" => 1,
        other => return Err(bad(path, format!("magic {other:?}, expected \"PF\" or \"Pf\""))),
    };
    let side = |t: String, what: &str| match t.parse::<u64>() {
        Ok(v) if v >= 1 => Ok(v),
        _ => Err(bad(path, format!("{what} {t:?} is not a whole number of at least 1"))),
    };
    let width = side(token()?, "width")?;
    let height = side(token()?, "height")?;
    let scale_token = token()?;
    let scale = scale_token.parse::<f64>().unwrap_or(f64::NAN);
    if !scale.is_finite() || scale == 0.0 {
        return Err(bad(path, format!("scale {scale_token:?} is not a finite, non-zero number")));
    }
    let samples_declared = width.saturating_mul(height).saturating_mul(channels as u64);
    if samples_declared > max_samples {
        return Err(bad(
            path,
            format!(
                "{width}×{height}×{channels} is above the limit of {max_samples} samples (HUSH_MAX_EXR_SAMPLES raises it)"
            ),
        ));
    }
    let (width, height) = (width as usize, height as usize);
    let data_start = pos + 1;
    let n = samples_declared as usize; // checked above: at most the sample limit
    if data_start > bytes.len() || bytes.len() - data_start != 4 * n {
        return Err(bad(
            path,
            format!(
                "{width}×{height}×{channels} needs {} bytes of samples, the file has {}",
                4 * n,
                bytes.len().saturating_sub(data_start)
            ),
        ));
    }
    let little = scale < 0.0;
    let samples = bytes[data_start..].chunks_exact(4).map(|b| {
        let b: [u8; 4] = b.try_into().expect("4 bytes");
        if little { f32::from_le_bytes(b) } else { f32::from_be_bytes(b) }
    });
    let rows: Vec<f32> = samples.collect();
    let row = width * channels;
    let data = rows.chunks_exact(row).rev().flatten().copied().collect();
    Image::new(width, height, channels, data)
}

/// Writes an RGB or one-channel image as a little-endian PFM file, atomically.
pub fn write_pfm(path: impl AsRef<Path>, image: &Image) -> Result<()> {
    let path = path.as_ref();
    let magic = match image.channels {
        3 => "PF",
        1 => "Pf",
        c => return Err(Error::Shape(format!("{}: PFM holds 1 or 3 channels, the image has {c}", path.display()))),
    };
    let mut bytes = format!("{magic}\n{} {}\n-1.0\n", image.width, image.height).into_bytes();
    for row in image.data.chunks_exact(image.width * image.channels).rev() {
        bytes.extend(row.iter().flat_map(|v| v.to_le_bytes()));
    }
    write_atomic(path, |tmp| std::fs::write(tmp, &bytes)).map_err(|source| Error::File {
        path: path.into(),
        action: "write",
        source,
    })
}
