//! [`Image`]: an interleaved (HWC) f32 image with any number of channels.

use std::ops::Range;

use crate::{Error, Result};

/// A row-major, interleaved f32 image: sample `(x, y, c)` is at `(y * width + x) * channels + c`.
///
/// All AOVs of hush are `Image`s: radiance (3 channels), albedo, normals, diffuse, specular and stacks of
/// them made with [`Image::concat_channels`]. The fields are public; the constructors check that
/// `data.len() == width * height * channels`, and the methods assume it.
#[derive(Clone, PartialEq)]
pub struct Image {
    pub width: usize,
    pub height: usize,
    pub channels: usize,
    pub data: Vec<f32>,
}

impl std::fmt::Debug for Image {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        // Never dump a quarter of a million samples into a test failure.
        write!(f, "Image({}x{}x{}, {} samples)", self.width, self.height, self.channels, self.data.len())
    }
}

impl Image {
    /// Wraps `data`; fails unless `data.len() == width * height * channels`.
    pub fn new(width: usize, height: usize, channels: usize, data: Vec<f32>) -> Result<Self> {
        let expected = width.checked_mul(height).and_then(|n| n.checked_mul(channels));
        if expected != Some(data.len()) {
            return Err(Error::Shape(format!(
                "image data has {} samples but {width}x{height}x{channels} needs {}",
                data.len(),
                expected.map_or("more than usize::MAX".to_string(), |n| n.to_string())
            )));
        }
        Ok(Image { width, height, channels, data })
    }

    /// An image of zeros.
    pub fn zeros(width: usize, height: usize, channels: usize) -> Self {
        Image { width, height, channels, data: vec![0.0; width * height * channels] }
    }

    /// An image whose sample `(x, y, c)` is `f(x, y, c)`.
    pub fn from_fn(
        width: usize,
        height: usize,
        channels: usize,
        mut f: impl FnMut(usize, usize, usize) -> f32,
    ) -> Self {
        let mut data = Vec::with_capacity(width * height * channels);
        for y in 0..height {
            for x in 0..width {
                for c in 0..channels {
                    data.push(f(x, y, c));
                }
            }
        }
        Image { width, height, channels, data }
    }

    /// `"WxHxC"`, for messages.
    pub fn size_string(&self) -> String {
        format!("{}x{}x{}", self.width, self.height, self.channels)
    }

    /// The samples of pixel `(x, y)`. Panics when out of bounds.
    pub fn pixel(&self, x: usize, y: usize) -> &[f32] {
        assert!(x < self.width && y < self.height, "pixel ({x}, {y}) outside {}", self.size_string());
        let i = (y * self.width + x) * self.channels;
        &self.data[i..i + self.channels]
    }

    /// The samples of pixel `(x, y)`, mutable. Panics when out of bounds.
    pub fn pixel_mut(&mut self, x: usize, y: usize) -> &mut [f32] {
        assert!(x < self.width && y < self.height, "pixel ({x}, {y}) outside {}", self.size_string());
        let i = (y * self.width + x) * self.channels;
        &mut self.data[i..i + self.channels]
    }

    /// The `w`×`h` window whose top-left pixel is `(x, y)`.
    pub fn crop(&self, x: usize, y: usize, w: usize, h: usize) -> Result<Image> {
        if x + w > self.width || y + h > self.height {
            return Err(Error::Shape(format!(
                "crop {w}x{h} at ({x}, {y}) does not fit in a {} image",
                self.size_string()
            )));
        }
        let c = self.channels;
        let mut data = Vec::with_capacity(w * h * c);
        for row in y..y + h {
            let start = (row * self.width + x) * c;
            data.extend_from_slice(&self.data[start..start + w * c]);
        }
        Ok(Image { width: w, height: h, channels: c, data })
    }

    /// Stacks the channels of same-sized images: `[color(3), albedo(3)]` gives 6 channels per pixel.
    pub fn concat_channels(images: &[&Image]) -> Result<Image> {
        let Some(first) = images.first() else {
            return Err(Error::Shape("concat_channels: no images given".into()));
        };
        for (i, im) in images.iter().enumerate() {
            if (im.width, im.height) != (first.width, first.height) {
                return Err(Error::Shape(format!(
                    "concat_channels: image 0 is {} but image {i} is {}; all must have the same width and height",
                    first.size_string(),
                    im.size_string()
                )));
            }
        }
        let channels: usize = images.iter().map(|im| im.channels).sum();
        let pixels = first.width * first.height;
        let mut data = Vec::with_capacity(pixels * channels);
        for p in 0..pixels {
            for im in images {
                data.extend_from_slice(&im.data[p * im.channels..(p + 1) * im.channels]);
            }
        }
        Ok(Image { width: first.width, height: first.height, channels, data })
    }

    /// The channels in `range`, e.g. `0..3` for the color of a stacked input.
    pub fn select_channels(&self, range: Range<usize>) -> Result<Image> {
        if range.start >= range.end || range.end > self.channels {
            return Err(Error::Shape(format!(
                "select_channels {range:?} is empty or outside the {} channels of a {} image",
                self.channels,
                self.size_string()
            )));
        }
        let data = self.data.chunks_exact(self.channels).flat_map(|p| &p[range.clone()]).copied().collect();
        Ok(Image { width: self.width, height: self.height, channels: range.len(), data })
    }

    /// How many samples are NaN or ±Inf.
    pub fn count_non_finite(&self) -> usize {
        self.data.iter().filter(|v| !v.is_finite()).count()
    }

    /// `(x, y, channel, value)` of the first sample for which `bad` holds, in row-major order.
    pub fn find_first(&self, bad: impl Fn(f32) -> bool) -> Option<(usize, usize, usize, f32)> {
        let i = self.data.iter().position(|&v| bad(v))?;
        let (p, c) = (i / self.channels, i % self.channels);
        Some((p % self.width, p / self.width, c, self.data[i]))
    }

    /// Mean of each channel (accumulated in f64). Empty images give zeros.
    pub fn mean(&self) -> Vec<f64> {
        let mut sum = vec![0.0f64; self.channels];
        for p in self.data.chunks_exact(self.channels.max(1)) {
            for (s, &v) in sum.iter_mut().zip(p) {
                *s += f64::from(v);
            }
        }
        let n = (self.width * self.height).max(1) as f64;
        sum.iter().map(|s| s / n).collect()
    }

    /// Averages each `k`×`k` block into one pixel (e.g. a 2048² reference to 512² with `k = 4`).
    /// Width and height must be multiples of `k`.
    pub fn downsample_box(&self, k: usize) -> Result<Image> {
        if k == 0 || !self.width.is_multiple_of(k) || !self.height.is_multiple_of(k) {
            return Err(Error::Shape(format!(
                "downsample_box({k}): the size of a {} image is not a positive multiple of {k}; crop it first",
                self.size_string()
            )));
        }
        let (w, h, c) = (self.width / k, self.height / k, self.channels);
        let mut sum = vec![0.0f64; w * h * c];
        for y in 0..self.height {
            for x in 0..self.width {
                let dst = ((y / k) * w + x / k) * c;
                for (s, &v) in sum[dst..dst + c].iter_mut().zip(self.pixel(x, y)) {
                    *s += f64::from(v);
                }
            }
        }
        let scale = 1.0 / (k * k) as f64;
        let data = sum.into_iter().map(|s| (s * scale) as f32).collect();
        Ok(Image { width: w, height: h, channels: c, data })
    }

    /// Fails unless `self` and `other` have the same width, height and channel count.
    /// `what` names the pair in the message, e.g. `"denoised vs reference"`.
    pub fn check_same_size(&self, other: &Image, what: &str) -> Result<()> {
        if (self.width, self.height, self.channels) != (other.width, other.height, other.channels) {
            return Err(Error::Shape(format!(
                "{what}: sizes differ ({} vs {})",
                self.size_string(),
                other.size_string()
            )));
        }
        Ok(())
    }
}
