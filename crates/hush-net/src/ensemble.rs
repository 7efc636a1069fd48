//! Test-time ensembles of one network: the image turned by the symmetries of the square (flips and the
//! transpose: the dihedral group of order 8), denoised in each pose and turned back, the outputs averaged; and
//! the step that uses their disagreement, [`restore_low_band`].
//!
//! A U-Net trained with flips and transposes (OIDN's augmentations, hush's too) should give the same image in
//! every pose; it does not quite, and the mean of the poses is a better estimate than any one of them (the
//! self-ensemble of super-resolution, Lim et al. 2017, "EDSR+"). Where the poses disagree, the network is
//! unsure.

use candle_core::Result;

use crate::transfer::{DISPLAY_WHITE, autoexposure};

/// How many poses there are: identity, flip x, flip y, both (a half turn), and each of those after the
/// transpose.
pub const POSES: usize = 8;

/// What each pose does, in order: what reports say of the first N.
pub const POSE_NAMES: [&str; POSES] = [
    "as it is",
    "flipped in x",
    "flipped in y",
    "flipped in both",
    "transposed",
    "transposed then flipped in x",
    "transposed then flipped in y",
    "transposed then flipped in both",
];

/// Pose `k` (0..[`POSES`]) of an interleaved `width × height × channels` image: the transpose first where bit 2
/// is set, then a flip of x (bit 0) and of y (bit 1). Returns the pixels and the new width and height (swapped
/// by the transpose). Poses 0..2 flip x only; 0..4 are the flips without the transpose.
pub fn pose(data: &[f32], width: usize, height: usize, channels: usize, k: usize) -> (Vec<f32>, usize, usize) {
    assert!(k < POSES, "pose: k must be below {POSES}, got {k}");
    assert_eq!(data.len(), width * height * channels, "pose: data must hold width * height * channels values");
    let transpose = k & 4 != 0;
    let (w, h) = if transpose { (height, width) } else { (width, height) };
    let mut out = Vec::with_capacity(data.len());
    for y in 0..h {
        for x in 0..w {
            let (x, y) = (if k & 1 != 0 { w - 1 - x } else { x }, if k & 2 != 0 { h - 1 - y } else { y });
            let (sx, sy) = if transpose { (y, x) } else { (x, y) };
            let p = (sy * width + sx) * channels;
            out.extend_from_slice(&data[p..p + channels]);
        }
    }
    (out, w, h)
}

/// Undoes [`pose`] `k`: `data` is an image of the posed size `width × height` (as [`pose`] returned it); the
/// result has the original size, `(height, width)` where the pose transposed.
pub fn unpose(data: &[f32], width: usize, height: usize, channels: usize, k: usize) -> Vec<f32> {
    assert!(k < POSES, "unpose: k must be below {POSES}, got {k}");
    assert_eq!(data.len(), width * height * channels, "unpose: data must hold width * height * channels values");
    let transpose = k & 4 != 0;
    let (w0, h0) = if transpose { (height, width) } else { (width, height) };
    let mut out = vec![0.0; data.len()];
    for y in 0..height {
        for x in 0..width {
            let (fx, fy) = (if k & 1 != 0 { width - 1 - x } else { x }, if k & 2 != 0 { height - 1 - y } else { y });
            let (sx, sy) = if transpose { (fy, fx) } else { (fx, fy) };
            let (q, p) = ((sy * w0 + sx) * channels, (y * width + x) * channels);
            out[q..q + channels].copy_from_slice(&data[p..p + channels]);
        }
    }
    debug_assert_eq!(out.len(), w0 * h0 * channels);
    out
}

/// Where several estimates of one image disagree, the render's own coarse content is often worth more: puts
/// back into `out` (their mean) the low band of the input's difference from it, weighted per pixel by how
/// unsure the estimates are there against how noisy the input's low band is.
///
/// With `G` a Gaussian of std `sigma` pixels (mirrored at the borders) and values clamped at the level the
/// display shows as white (at the input's autoexposure: differences above it are invisible and would spread
/// into halos around emitters), for each pixel:
/// - the input's low band has variance `s² = Σ G(q)² · v(q)`, `v` the channel mean of `variance` (the
///   render's variance of each pixel's mean);
/// - the estimates' low bands `G * o_i` spread by `e²`, their sample variance (channel mean): a lower bound on
///   the error of their mean, since their errors share what the network gets wrong in every pose;
/// - `out += e² / (e² + s²) · G * (color − out)`, the weight of two independent estimates with those
///   variances, clamped ≥ 0 after.
///
/// `outputs` are the estimates (at least 2; `out` is their mean), every image interleaved RGB of
/// `width × height`. Where no pixel has a variance above 0 (one sample per pixel has no estimate), nothing
/// changes. Returns the mean weight.
pub fn restore_low_band(
    out: &mut [f32],
    outputs: &[&[f32]],
    color: &[f32],
    variance: &[f32],
    width: usize,
    height: usize,
    sigma: f32,
) -> Result<f32> {
    let n = width * height * 3;
    if [out.len(), color.len(), variance.len()].into_iter().chain(outputs.iter().map(|o| o.len())).any(|l| l != n) {
        candle_core::bail!("restore_low_band: every image must be {width}x{height} RGB ({n} values)")
    }
    if outputs.len() < 2 {
        candle_core::bail!(
            "restore_low_band: needs at least 2 estimates to measure their spread, got {}",
            outputs.len()
        )
    }
    if !(sigma.is_finite() && sigma > 0.0) {
        candle_core::bail!("restore_low_band: sigma must be positive and finite, got {sigma}")
    }
    if !variance.iter().any(|&v| v > 0.0) {
        return Ok(0.0);
    }
    let white = DISPLAY_WHITE / autoexposure(color, width, height);
    let clamp = |v: f32| if v.is_finite() { v.min(white) } else { 0.0 };
    let kernel = gaussian(sigma);
    let squared: Vec<f32> = kernel.iter().map(|k| k * k).collect();
    let mean_var: Vec<f32> = variance
        .chunks_exact(3)
        .map(|v| v.iter().map(|&v| if v.is_finite() { v.max(0.0) } else { 0.0 }).sum::<f32>() / 3.0)
        .collect();
    let s2 = blur(&mean_var, width, height, 1, &squared);
    let bands: Vec<Vec<f32>> = outputs
        .iter()
        .map(|o| blur(&o.iter().map(|&v| clamp(v)).collect::<Vec<_>>(), width, height, 3, &kernel))
        .collect();
    let count = bands.len() as f32;
    let difference: Vec<f32> = color.iter().zip(out.iter()).map(|(&c, &o)| clamp(c) - clamp(o)).collect();
    let residual = blur(&difference, width, height, 3, &kernel);
    let mut total = 0.0f64;
    for (p, &s2) in s2.iter().enumerate() {
        let mut e2 = 0.0f32;
        for c in 0..3 {
            let i = p * 3 + c;
            let mean = bands.iter().map(|b| b[i]).sum::<f32>() / count;
            e2 += bands.iter().map(|b| (b[i] - mean) * (b[i] - mean)).sum::<f32>() / (count - 1.0);
        }
        let e2 = e2 / 3.0;
        let w = if e2 + s2 > 0.0 { e2 / (e2 + s2) } else { 0.0 };
        for c in 0..3 {
            let i = p * 3 + c;
            out[i] = (out[i] + w * residual[i]).max(0.0);
        }
        total += f64::from(w);
    }
    Ok((total / (width * height) as f64) as f32)
}

/// A normalized Gaussian of std `sigma`, radius `ceil(3·sigma)`.
fn gaussian(sigma: f32) -> Vec<f32> {
    let r = (3.0 * sigma).ceil() as i64;
    let k: Vec<f32> = (-r..=r).map(|x| (-(x * x) as f32 / (2.0 * sigma * sigma)).exp()).collect();
    let sum: f32 = k.iter().sum();
    k.into_iter().map(|v| v / sum).collect()
}

/// Mirrors index `i` into `0..n` (the edge pixel not repeated: `-1 → 1`), repeating the mirror as needed.
fn mirror(i: i64, n: usize) -> usize {
    let n = n as i64;
    if n == 1 {
        return 0;
    }
    let period = 2 * (n - 1);
    let m = i.rem_euclid(period);
    (if m < n { m } else { period - m }) as usize
}

/// The separable convolution of an interleaved image with `kernel` along x then y, mirrored at the borders.
fn blur(data: &[f32], width: usize, height: usize, channels: usize, kernel: &[f32]) -> Vec<f32> {
    let r = (kernel.len() / 2) as i64;
    let mut rows = vec![0.0f32; data.len()];
    for y in 0..height {
        for x in 0..width {
            for (j, &k) in kernel.iter().enumerate() {
                let sx = mirror(x as i64 + j as i64 - r, width);
                for c in 0..channels {
                    rows[(y * width + x) * channels + c] += k * data[(y * width + sx) * channels + c];
                }
            }
        }
    }
    let mut out = vec![0.0f32; data.len()];
    for y in 0..height {
        for (j, &k) in kernel.iter().enumerate() {
            let sy = mirror(y as i64 + j as i64 - r, height);
            for x in 0..width {
                for c in 0..channels {
                    out[(y * width + x) * channels + c] += k * rows[(sy * width + x) * channels + c];
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The names say what the poses do: pose 3 flips both ways (the first pixel becomes the last), pose 4
    /// transposes.
    #[test]
    fn pose_names_match_the_poses() {
        let image: Vec<f32> = (0..6).map(|v| v as f32).collect(); // 3×2, one channel
        assert_eq!(POSE_NAMES[3], "flipped in both");
        assert_eq!(pose(&image, 3, 2, 1, 3).0, vec![5.0, 4.0, 3.0, 2.0, 1.0, 0.0]);
        assert_eq!(POSE_NAMES[4], "transposed");
        assert_eq!(pose(&image, 3, 2, 1, 4).0, vec![0.0, 3.0, 1.0, 4.0, 2.0, 5.0]);
        assert_eq!(POSE_NAMES[5], "transposed then flipped in x");
        assert_eq!(pose(&image, 3, 2, 1, 5).0, vec![3.0, 0.0, 4.0, 1.0, 5.0, 2.0]);
    }

    #[test]
    fn mirror_reflects_without_repeating_the_edge() {
        let got: Vec<usize> = (-3..7).map(|i| mirror(i, 4)).collect();
        assert_eq!(got, vec![3, 2, 1, 0, 1, 2, 3, 2, 1, 0]);
        assert_eq!(mirror(-5, 1), 0);
    }

    #[test]
    fn blur_keeps_a_constant_and_the_kernel_sums_to_one() {
        let k = gaussian(1.5);
        assert!((k.iter().sum::<f32>() - 1.0).abs() < 1e-6);
        let out = blur(&[2.0; 5 * 3 * 2], 5, 3, 2, &k);
        assert!(out.iter().all(|v| (v - 2.0).abs() < 1e-5), "{out:?}");
    }
}
