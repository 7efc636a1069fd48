//! LDR-FLIP [Andersson et al. 2020, "FLIP: A Difference Evaluator for Alternating Images", HPG], ported from
//! NVIDIA's reference implementation (NVlabs/flip, `FLIP.h`, the code behind PyPI `flip-evaluator` 1.7): the
//! same separable filters, constants, clamping and edge handling (clamp-to-edge), computed in f32 like the
//! reference, so that the error map agrees to rounding (see the test `flip_matches_flip_evaluator`).
//!
//! Steps, on two sRGB-encoded images in [0, 1] (clamped): linearize, convert to YCxCz (opponent space, D65);
//! filter with the contrast sensitivity functions (Gaussians for Y and Cx, a sum of two for Cz), clamp to
//! linear RGB [0, 1], convert to CIELab, apply the Hunt adjustment, take the HyAB distance, compress it
//! (`^0.7`) and remap to [0, 1]; in parallel, detect edges and points (1st/2nd derivatives of a Gaussian of
//! std 0.5·0.082·ppd on normalized luminance) in both images; the final per-pixel error is
//! `color_error ^ (1 − feature_difference)`. The mean is the plain mean of that map.

// FLIP.h's `FLIP::PI` (3.14159265358979f) rounds to this same f32.
use std::f32::consts::PI;

use hush_dataset::{Image, check_finite};

use crate::{Error, Result};

/// Pixels per degree of the reference implementation's default viewing conditions: a 0.7 m wide 3840-pixel
/// monitor watched from 0.7 m: `0.7 · 3840 / 0.7 · π / 180` ≈ 67.02.
pub const DEFAULT_PPD: f32 = 0.7 * (3840.0 / 0.7) * (PI / 180.0);

// FLIP's constants (FLIP.h `FLIPConstants`): color-difference exponent, cut-off fraction and its target,
// feature filter width in degrees, feature exponent.
const GQC: f32 = 0.7;
const GPC: f32 = 0.4;
const GPT: f32 = 0.95;
const GW: f32 = 0.082;
const GQF: f32 = 0.5;

// CSF Gaussians (a, b) per channel of YCxCz; Cz is a sum of two (FLIP.h `GaussianConstants`).
const A1: [f32; 3] = [1.0, 1.0, 34.1];
const B1: [f32; 3] = [0.0047, 0.0053, 0.04];
const A2: [f32; 3] = [0.0, 0.0, 13.5];
const B2: [f32; 3] = [1.0e-5, 1.0e-5, 0.025];

const ILLUMINANT: [f32; 3] = [0.950_428_5, 1.0, 1.088_900_4];
const INV_ILLUMINANT: [f32; 3] = [1.052_156_9, 1.0, 0.918_357_7];

/// The result of [`flip`]: the per-pixel error map (one channel, values in [0, 1]) and its mean.
#[derive(Clone, Debug)]
pub struct Flip {
    /// Per-pixel LDR-FLIP error, a 1-channel image of the inputs' size.
    pub map: Image,
    /// Mean of `map`.
    pub mean: f64,
}

/// LDR-FLIP of `test` against `reference`, both sRGB-encoded RGB images in [0, 1] (for hush: the output of
/// [`crate::tonemap`], with the reference's exposure), at [`DEFAULT_PPD`]. Values outside [0, 1] are clamped
/// as in the reference implementation. Errors on size mismatch, non-RGB or NaN/Inf input.
pub fn flip(test: &Image, reference: &Image) -> Result<Flip> {
    flip_with_ppd(test, reference, DEFAULT_PPD)
}

/// [`flip`] at a given number of pixels per degree of visual angle (> 0).
pub fn flip_with_ppd(test: &Image, reference: &Image, ppd: f32) -> Result<Flip> {
    if (test.width, test.height, test.channels) != (reference.width, reference.height, reference.channels) {
        return Err(Error::Shape(format!(
            "FLIP: test image is {} but the reference is {}",
            test.size_string(),
            reference.size_string()
        )));
    }
    if reference.channels != 3 || reference.width == 0 || reference.height == 0 {
        return Err(Error::Shape(format!("FLIP: images must be non-empty RGB, got {}", reference.size_string())));
    }
    if !(ppd.is_finite() && ppd > 0.0) {
        return Err(Error::Shape(format!("FLIP: pixels per degree must be > 0, got {ppd}")));
    }
    check_finite("FLIP test image", test).map_err(Error::NonFinite)?;
    check_finite("FLIP reference image", reference).map_err(Error::NonFinite)?;

    let (w, h) = (reference.width, reference.height);
    let r = to_ycxcz(reference);
    let t = to_ycxcz(test);
    let color = color_difference(&r, &t, w, h, ppd);
    let features = feature_difference(&r, &t, w, h, ppd);
    let data: Vec<f32> = color.iter().zip(&features).map(|(&c, &f)| c.powf(1.0 - f)).collect();
    let mean = data.iter().map(|&v| f64::from(v)).sum::<f64>() / data.len() as f64;
    Ok(Flip { map: Image { width: w, height: h, channels: 1, data }, mean })
}

type C3 = [f32; 3];

fn srgb_to_linear(s: f32) -> f32 {
    if s <= 0.04045 { s / 12.92 } else { ((s + 0.055) / 1.055).powf(2.4) }
}

fn linear_rgb_to_xyz(c: C3) -> C3 {
    let m = [
        [10135552.0 / 24577794.0, 8788810.0 / 24577794.0, 4435075.0 / 24577794.0],
        [2613072.0 / 12288897.0, 8788810.0 / 12288897.0, 887015.0 / 12288897.0],
        [1425312.0 / 73733382.0, 8788810.0 / 73733382.0, 70074185.0 / 73733382.0],
    ];
    mat(&m, c)
}

fn xyz_to_linear_rgb(c: C3) -> C3 {
    let m = [
        [3.241_003_3, -1.537_398_9, -0.498_615_87],
        [-0.969_224_3, 1.875_930_1, 0.041_554_224],
        [0.055_639_423, -0.204_011_2, 1.057_148_9],
    ];
    mat(&m, c)
}

fn mat(m: &[[f32; 3]; 3], c: C3) -> C3 {
    [
        m[0][0] * c[0] + m[0][1] * c[1] + m[0][2] * c[2],
        m[1][0] * c[0] + m[1][1] * c[1] + m[1][2] * c[2],
        m[2][0] * c[0] + m[2][1] * c[1] + m[2][2] * c[2],
    ]
}

fn xyz_to_ycxcz(c: C3) -> C3 {
    let [x, y, z] = [c[0] * INV_ILLUMINANT[0], c[1] * INV_ILLUMINANT[1], c[2] * INV_ILLUMINANT[2]];
    [116.0 * y - 16.0, 500.0 * (x - y), 200.0 * (y - z)]
}

fn ycxcz_to_xyz(c: C3) -> C3 {
    let y = (c[0] + 16.0) / 116.0;
    let (cx, cz) = (c[1] / 500.0, c[2] / 200.0);
    [(y + cx) * ILLUMINANT[0], y * ILLUMINANT[1], (y - cz) * ILLUMINANT[2]]
}

fn xyz_to_lab(c: C3) -> C3 {
    const DELTA: f32 = 6.0 / 29.0;
    let f = |v: f32| {
        if v > DELTA * DELTA * DELTA { v.powf(1.0 / 3.0) } else { v / (3.0 * DELTA * DELTA) + 4.0 / 29.0 }
    };
    let [x, y, z] = [f(c[0] * INV_ILLUMINANT[0]), f(c[1] * INV_ILLUMINANT[1]), f(c[2] * INV_ILLUMINANT[2])];
    [116.0 * y - 16.0, 500.0 * (x - y), 200.0 * (y - z)]
}

fn hunt(l: f32, c: f32) -> f32 {
    0.01 * l * c
}

fn hyab(a: C3, b: C3) -> f32 {
    (a[0] - b[0]).abs() + ((a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

fn hunt_lab(c: C3) -> C3 {
    [c[0], hunt(c[0], c[1]), hunt(c[0], c[2])]
}

/// Clamped sRGB → linear → YCxCz, per pixel.
fn to_ycxcz(image: &Image) -> Vec<C3> {
    image
        .data
        .chunks_exact(3)
        .map(|p| {
            let lin = [0, 1, 2].map(|c| srgb_to_linear(p[c].clamp(0.0, 1.0)));
            xyz_to_ycxcz(linear_rgb_to_xyz(lin))
        })
        .collect()
}

fn gaussian_ab(x2: f32, a: f32, b: f32) -> f32 {
    a * (PI / b).sqrt() * (-(PI * PI) * x2 / b).exp()
}

fn gaussian_sqrt(x2: f32, a: f32, b: f32) -> f32 {
    (a * (PI / b).sqrt()).sqrt() * (-(PI * PI) * x2 / b).exp()
}

/// The separable CSF filters: per tap `[Y, Cx]` and `[Cz₁, Cz₂]` (Cz is `Cz₁⊗Cz₁ + Cz₂⊗Cz₂`).
fn spatial_filters(ppd: f32) -> (Vec<[f32; 2]>, Vec<[f32; 2]>) {
    let max_b = B1.iter().chain(&B2).fold(0.0f32, |m, &b| m.max(b));
    let radius = (3.0 * (max_b / (2.0 * PI * PI)).sqrt() * ppd).ceil() as i64;
    let dx = 1.0 / ppd;
    let (mut ycx, mut cz) = (Vec::new(), Vec::new());
    let (mut sum_ycx, mut sum_cz) = ([0.0f32; 2], [0.0f32; 2]);
    for i in -radius..=radius {
        let x = i as f32 * dx;
        let x2 = x * x;
        let a = [gaussian_ab(x2, A1[0], B1[0]), gaussian_ab(x2, A1[1], B1[1])];
        let b = [gaussian_sqrt(x2, A1[2], B1[2]), gaussian_sqrt(x2, A2[2], B2[2])];
        for k in 0..2 {
            sum_ycx[k] += a[k];
            sum_cz[k] += b[k];
        }
        ycx.push(a);
        cz.push(b);
    }
    let norm_cz = 1.0 / (sum_cz[0] * sum_cz[0] + sum_cz[1] * sum_cz[1]).sqrt();
    for v in &mut ycx {
        *v = [v[0] / sum_ycx[0], v[1] / sum_ycx[1]];
    }
    for v in &mut cz {
        *v = [v[0] * norm_cz, v[1] * norm_cz];
    }
    (ycx, cz)
}

/// Per-pixel color error after CSF filtering, remapped to [0, 1].
fn color_difference(r: &[C3], t: &[C3], w: usize, h: usize, ppd: f32) -> Vec<f32> {
    let (fy, fz) = spatial_filters(ppd);
    let half = (fy.len() / 2) as i64;
    let cmax = {
        let lab = |rgb: C3| hunt_lab(xyz_to_lab(linear_rgb_to_xyz(rgb)));
        hyab(lab([0.0, 1.0, 0.0]), lab([0.0, 0.0, 1.0])).powf(GQC)
    };
    let pccmax = GPC * cmax;
    // Horizontal pass: per image, [Y·gY, Cx·gCx, Cz·g₁, Cz·g₂].
    let horizontal = |img: &[C3]| -> Vec<[f32; 4]> {
        per_pixel(w, h, |x, y| {
            let mut acc = [0.0f32; 4];
            for i in -half..=half {
                let xx = (x as i64 + i).clamp(0, w as i64 - 1) as usize;
                let (a, b) = (fy[(i + half) as usize], fz[(i + half) as usize]);
                let c = img[y * w + xx];
                acc[0] += a[0] * c[0];
                acc[1] += a[1] * c[1];
                acc[2] += b[0] * c[2];
                acc[3] += b[1] * c[2];
            }
            acc
        })
    };
    let (hr, ht) = (horizontal(r), horizontal(t));
    let vertical = |img: &[[f32; 4]], x: usize, y: usize| -> C3 {
        let mut acc = [0.0f32; 4];
        for i in -half..=half {
            let yy = (y as i64 + i).clamp(0, h as i64 - 1) as usize;
            let (a, b) = (fy[(i + half) as usize], fz[(i + half) as usize]);
            let c = img[yy * w + x];
            acc[0] += a[0] * c[0];
            acc[1] += a[1] * c[1];
            acc[2] += b[0] * c[2];
            acc[3] += b[1] * c[3];
        }
        let rgb = xyz_to_linear_rgb(ycxcz_to_xyz([acc[0], acc[1], acc[2] + acc[3]])).map(|v| v.clamp(0.0, 1.0));
        hunt_lab(xyz_to_lab(linear_rgb_to_xyz(rgb)))
    };
    per_pixel(w, h, |x, y| {
        let d = hyab(vertical(&hr, x, y), vertical(&ht, x, y)).powf(GQC);
        if d < pccmax { d * (GPT / pccmax) } else { GPT + ((d - pccmax) / (cmax - pccmax)) * (1.0 - GPT) }
    })
}

/// Per tap: Gaussian, 1st and 2nd derivative, normalized as in the reference (Gaussian sums to 1, positive
/// and negative lobes of the derivatives to ±1).
fn feature_filter(ppd: f32) -> Vec<C3> {
    let sd = 0.5 * GW * ppd;
    let radius = (3.0 * sd).ceil() as i64;
    let (mut g_sum, mut dg_pos, mut dg_neg, mut ddg_pos, mut ddg_neg) = (0.0f32, 0.0f32, 0.0f32, 0.0f32, 0.0f32);
    let mut taps = Vec::new();
    for i in -radius..=radius {
        let x = i as f32;
        let g = (-(x * x) / (2.0 * sd * sd)).exp();
        g_sum += g;
        let dg = -x * g;
        if dg > 0.0 {
            dg_pos += dg;
        } else {
            dg_neg -= dg;
        }
        let ddg = (x * x / (sd * sd) - 1.0) * g;
        if ddg > 0.0 {
            ddg_pos += ddg;
        } else {
            ddg_neg -= ddg;
        }
        taps.push([g, dg, ddg]);
    }
    taps.iter()
        .map(|&[g, dg, ddg]| {
            [g / g_sum, dg / if dg > 0.0 { dg_pos } else { dg_neg }, ddg / if ddg > 0.0 { ddg_pos } else { ddg_neg }]
        })
        .collect()
}

/// Per-pixel feature (edge and point) difference in [0, 1].
fn feature_difference(r: &[C3], t: &[C3], w: usize, h: usize, ppd: f32) -> Vec<f32> {
    let filter = feature_filter(ppd);
    let half = (filter.len() / 2) as i64;
    // Horizontal pass on normalized luminance: [dx, ddx, gaussian].
    let horizontal = |img: &[C3]| -> Vec<C3> {
        per_pixel(w, h, |x, y| {
            let mut acc = [0.0f32; 3];
            for i in -half..=half {
                let xx = (x as i64 + i).clamp(0, w as i64 - 1) as usize;
                let f = filter[(i + half) as usize];
                let v = img[y * w + xx][0] * (1.0 / 116.0) + 16.0 / 116.0;
                acc[0] += f[1] * v;
                acc[1] += f[2] * v;
                acc[2] += f[0] * v;
            }
            acc
        })
    };
    let (hr, ht) = (horizontal(r), horizontal(t));
    // Vertical pass: returns (edge, point) magnitudes.
    let vertical = |img: &[C3], x: usize, y: usize| -> (f32, f32) {
        let (mut dx, mut ddx, mut dy, mut ddy) = (0.0f32, 0.0f32, 0.0f32, 0.0f32);
        for i in -half..=half {
            let yy = (y as i64 + i).clamp(0, h as i64 - 1) as usize;
            let f = filter[(i + half) as usize];
            let c = img[yy * w + x];
            dx += f[0] * c[0];
            ddx += f[0] * c[1];
            dy += f[1] * c[2];
            ddy += f[2] * c[2];
        }
        ((dx * dx + dy * dy).sqrt(), (ddx * ddx + ddy * ddy).sqrt())
    };
    let norm = 1.0 / 2.0f32.sqrt();
    per_pixel(w, h, |x, y| {
        let (er, pr) = vertical(&hr, x, y);
        let (et, pt) = vertical(&ht, x, y);
        (norm * (er - et).abs().max((pr - pt).abs())).powf(GQF)
    })
}

/// `f(x, y)` for every pixel, row-major, with the rows split between the machine's threads.
fn per_pixel<T: Copy + Default + Send>(w: usize, h: usize, f: impl Fn(usize, usize) -> T + Sync) -> Vec<T> {
    let mut out = vec![T::default(); w * h];
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get()).clamp(1, h.max(1));
    let rows_per = h.div_ceil(threads).max(1);
    std::thread::scope(|s| {
        for (chunk, rows) in out.chunks_mut(rows_per * w).enumerate() {
            let f = &f;
            s.spawn(move || {
                for (i, v) in rows.iter_mut().enumerate() {
                    *v = f(i % w, chunk * rows_per + i / w);
                }
            });
        }
    });
    out
}
