//! Firefly removal for references: hush's stand-in for ImageMagick's `-despeckle`.
//!
//! ImageMagick's despeckle is Crimmins' speckle-removal filter: per channel, a pixel that stands above its
//! neighbours is lowered step by step until it no longer does, so isolated one-pixel peaks vanish while
//! edges and areas (which have equally bright neighbours) survive. [`despeckle`] keeps that property with one
//! robust, documented rule that works on HDR values and keeps color:
//!
//! * a pixel's luminance `L` (Rec. 709) is compared with `M`, the largest luminance among its 8 neighbours
//!   (at the border, the neighbours that exist);
//! * if `L > factor × M`, the pixel is an isolated peak (a firefly) and its RGB is scaled by
//!   `factor × M / L`, i.e. clamped to `factor` times its brightest neighbour with its chromaticity kept;
//! * every other pixel is left exactly as it was. Decisions read the unfiltered image only, so the result
//!   does not depend on the scan order.
//!
//! Unlike a median, the maximum keeps every pixel that has at least one comparably bright neighbour: corners
//! and one-pixel-wide lines of a light source, and thin highlights, are untouched. A pair of adjacent
//! fireflies survives (as with Crimmins' single pass); at reference sample counts fireflies are isolated.
//! Like despeckle, the clamp removes energy; the fraction removed is returned so it can be recorded.

use crate::{Error, Image, Result};

/// The default clamp factor for references: a pixel 4× brighter than all of its neighbours is a firefly.
/// At reference sample counts the relative noise per pixel is a few percent, so no legitimate pixel stands
/// that far above every neighbour unless the scene has sub-pixel light sources.
pub const DEFAULT_FIREFLY_FACTOR: f32 = 4.0;

/// What [`despeckle`] changed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DespeckleStats {
    pub clamped_pixels: usize,
    /// Removed luminance over the image's total luminance (0 for a black image).
    pub energy_removed: f64,
}

/// Rec. 709 luminance of an RGB pixel.
pub fn luminance(rgb: &[f32]) -> f32 {
    0.2126 * rgb[0] + 0.7152 * rgb[1] + 0.0722 * rgb[2]
}

/// Clamps isolated peaks of an RGB image in place (see the module documentation). `factor` must be at least
/// 1; `factor = f32::INFINITY` leaves the image unchanged.
pub fn despeckle(image: &mut Image, factor: f32) -> Result<DespeckleStats> {
    if image.channels != 3 {
        return Err(Error::Shape(format!("despeckle needs an RGB image, got {}", image.size_string())));
    }
    if factor.is_nan() || factor < 1.0 {
        return Err(Error::Shape(format!("despeckle factor {factor} must be at least 1")));
    }
    let (w, h) = (image.width, image.height);
    let lum: Vec<f32> = image.data.chunks_exact(3).map(luminance).collect();
    let total: f64 = lum.iter().map(|&l| f64::from(l.max(0.0))).sum();
    let mut stats = DespeckleStats { clamped_pixels: 0, energy_removed: 0.0 };
    let mut removed = 0.0f64;
    for y in 0..h {
        for x in 0..w {
            let l = lum[y * w + x];
            let mut max = f32::NEG_INFINITY;
            for ny in y.saturating_sub(1)..(y + 2).min(h) {
                for nx in x.saturating_sub(1)..(x + 2).min(w) {
                    if (nx, ny) != (x, y) {
                        max = max.max(lum[ny * w + nx]);
                    }
                }
            }
            if max == f32::NEG_INFINITY {
                continue; // a 1×1 image has no neighbours
            }
            let limit = factor * max.max(0.0);
            if l > limit {
                let scale = limit / l;
                image.pixel_mut(x, y).iter_mut().for_each(|v| *v *= scale);
                stats.clamped_pixels += 1;
                removed += f64::from(l - limit);
            }
        }
    }
    stats.energy_removed = if total > 0.0 { removed / total } else { 0.0 };
    Ok(stats)
}
