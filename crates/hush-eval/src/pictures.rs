//! Pictures for people: tonemapped 8-bit images, crops side by side and difference images that mark the
//! pixels off by more than 3 % and 10 % (as the thesis's figures 7.3 and 7.7, which mark one threshold in
//! black each).
//!
//! "Off by" is measured on the evaluation tonemap ([`crate::tonemap`] with the reference's exposure): the
//! largest absolute difference over the pixel's channels, in [0, 1]. Pixels above [`MARK_HIGH`] are drawn
//! in [`HIGH_COLOR`] (red), above [`MARK_LOW`] in [`LOW_COLOR`] (yellow), the others as the reference in
//! dimmed grey.

use hush_dataset::Image;
use serde::{Deserialize, Serialize};

use crate::{Error, Result, tonemap};

/// The lower threshold of [`error_marks`]: 3 % of the tonemapped range.
pub const MARK_LOW: f32 = 0.03;
/// The upper threshold of [`error_marks`]: 10 % of the tonemapped range.
pub const MARK_HIGH: f32 = 0.10;
/// Color of pixels off by more than [`MARK_LOW`] (and at most [`MARK_HIGH`]).
pub const LOW_COLOR: [u8; 3] = [255, 200, 0];
/// Color of pixels off by more than [`MARK_HIGH`].
pub const HIGH_COLOR: [u8; 3] = [220, 0, 0];

/// An 8-bit RGB picture.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Rgb8 {
    pub width: usize,
    pub height: usize,
    /// Row-major RGB triples.
    pub data: Vec<u8>,
}

impl Rgb8 {
    /// The evaluation tonemap of `image` (RGB, linear) at `exposure`, as 8 bits.
    pub fn tonemapped(image: &Image, exposure: f32) -> Result<Rgb8> {
        rgb_only(image)?;
        let t = tonemap(image, exposure);
        Ok(Rgb8 { width: t.width, height: t.height, data: t.data.iter().map(|&v| to_u8(v)).collect() })
    }

    /// The `w`×`h` window at (`x`, `y`), clipped to the picture.
    pub fn crop(&self, x: usize, y: usize, w: usize, h: usize) -> Rgb8 {
        let (x, y) = (x.min(self.width), y.min(self.height));
        let (w, h) = (w.min(self.width - x), h.min(self.height - y));
        let mut data = Vec::with_capacity(w * h * 3);
        for row in y..y + h {
            let start = (row * self.width + x) * 3;
            data.extend_from_slice(&self.data[start..start + w * 3]);
        }
        Rgb8 { width: w, height: h, data }
    }

    /// Every pixel repeated `k`×`k` times (nearest neighbour), so small crops stay sharp when shown.
    pub fn upscale(&self, k: usize) -> Rgb8 {
        let k = k.max(1);
        let (w, h) = (self.width * k, self.height * k);
        let mut data = Vec::with_capacity(w * h * 3);
        for y in 0..h {
            for x in 0..w {
                let i = ((y / k) * self.width + x / k) * 3;
                data.extend_from_slice(&self.data[i..i + 3]);
            }
        }
        Rgb8 { width: w, height: h, data }
    }

    /// PNG bytes.
    pub fn to_png(&self) -> Result<Vec<u8>> {
        let side = |n: usize| u32::try_from(n).map_err(|_| Error::Picture(format!("picture side {n} is too large")));
        crate::plot::png_rgb8(&self.data, side(self.width)?, side(self.height)?)
    }
}

/// Fractions of pixels off by more than [`MARK_LOW`] and more than [`MARK_HIGH`].
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Marks {
    pub over_low: f64,
    pub over_high: f64,
}

/// The difference picture of `test` against `reference` (both linear RGB of one size), tonemapped at
/// `exposure`, and the fractions of marked pixels.
pub fn error_marks(test: &Image, reference: &Image, exposure: f32) -> Result<(Rgb8, Marks)> {
    rgb_only(test)?;
    rgb_only(reference)?;
    if (test.width, test.height) != (reference.width, reference.height) {
        return Err(Error::Shape(format!(
            "difference picture: the test image is {} but the reference is {}",
            test.size_string(),
            reference.size_string()
        )));
    }
    let (t, r) = (tonemap(test, exposure), tonemap(reference, exposure));
    let mut data = Vec::with_capacity(t.data.len());
    let (mut low, mut high) = (0usize, 0usize);
    for (a, b) in t.data.chunks_exact(3).zip(r.data.chunks_exact(3)) {
        let off = a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0f32, f32::max);
        if off > MARK_HIGH {
            high += 1;
            low += 1;
            data.extend_from_slice(&HIGH_COLOR);
        } else if off > MARK_LOW {
            low += 1;
            data.extend_from_slice(&LOW_COLOR);
        } else {
            let grey = to_u8(0.25 + 0.5 * (0.2126 * b[0] + 0.7152 * b[1] + 0.0722 * b[2]));
            data.extend_from_slice(&[grey; 3]);
        }
    }
    let n = (t.width * t.height).max(1) as f64;
    let marks = Marks { over_low: low as f64 / n, over_high: high as f64 / n };
    Ok((Rgb8 { width: t.width, height: t.height, data }, marks))
}

/// The top-left corner of the `side`×`side` window (clipped to the image) where `test` differs most from
/// `reference` in mean absolute tonemapped error, searched on a grid of `side / 4` steps: the crop that shows
/// the noise best.
pub fn worst_window(test: &Image, reference: &Image, exposure: f32, side: usize) -> Result<(usize, usize)> {
    rgb_only(test)?;
    if (test.width, test.height) != (reference.width, reference.height) {
        return Err(Error::Shape(format!(
            "crop search: the test image is {} but the reference is {}",
            test.size_string(),
            reference.size_string()
        )));
    }
    let (t, r) = (tonemap(test, exposure), tonemap(reference, exposure));
    let (w, h) = (side.min(t.width), side.min(t.height));
    let step = (side / 4).max(1);
    // Per-pixel error, then a summed-area table for O(1) window sums.
    let mut sat = vec![0.0f64; (t.width + 1) * (t.height + 1)];
    for y in 0..t.height {
        for x in 0..t.width {
            let i = (y * t.width + x) * 3;
            let e: f32 = (0..3).map(|c| (t.data[i + c] - r.data[i + c]).abs()).sum();
            let s = |xx: usize, yy: usize| sat[yy * (t.width + 1) + xx];
            sat[(y + 1) * (t.width + 1) + x + 1] = f64::from(e) + s(x, y + 1) + s(x + 1, y) - s(x, y);
        }
    }
    let s = |xx: usize, yy: usize| sat[yy * (t.width + 1) + xx];
    let mut best = (0, 0, f64::NEG_INFINITY);
    let mut y = 0;
    while y + h <= t.height {
        let mut x = 0;
        while x + w <= t.width {
            let sum = s(x + w, y + h) - s(x, y + h) - s(x + w, y) + s(x, y);
            if sum > best.2 {
                best = (x, y, sum);
            }
            x += step;
        }
        y += step;
    }
    Ok((best.0, best.1))
}

fn to_u8(v: f32) -> u8 {
    (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8
}

fn rgb_only(image: &Image) -> Result<()> {
    if image.channels != 3 {
        return Err(Error::Shape(format!("pictures need RGB images, got a {} image", image.size_string())));
    }
    Ok(())
}
