//! Tables of the rough plastic, computed on the CPU as Mitsuba's `roughplastic` does: the
//! rough coat's directional albedo, integrated by Gauss–Legendre quadrature over the
//! visible-normal sample square.

use std::collections::HashMap;
use std::f64::consts::PI;
use std::sync::{LazyLock, Mutex};

/// Entries of the external-transmittance table, at cos θ = i / (N − 1); Mitsuba's
/// `MI_ROUGH_TRANSMITTANCE_RES`.
pub(crate) const TABLE_SIZE: usize = 64;

use hush_scene::Microfacet as Distribution;

type V3 = [f64; 3];

fn dot(a: V3, b: V3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn normalize(a: V3) -> V3 {
    let l = dot(a, a).sqrt();
    [a[0] / l, a[1] / l, a[2] / l]
}

/// Nodes and weights of the n-point Gauss–Legendre rule on [-1, 1] (Newton on P_n).
fn gauss_legendre(n: usize) -> Vec<(f64, f64)> {
    (0..n)
        .map(|i| {
            let mut x = (PI * (i as f64 + 0.75) / (n as f64 + 0.5)).cos();
            let mut dp = 0.0;
            for _ in 0..100 {
                let (mut p0, mut p1) = (1.0, x);
                for k in 2..=n {
                    let p2 = ((2 * k - 1) as f64 * x * p1 - (k - 1) as f64 * p0) / k as f64;
                    p0 = p1;
                    p1 = p2;
                }
                dp = n as f64 * (x * p1 - p0) / (x * x - 1.0);
                let dx = p1 / dp;
                x -= dx;
                if dx.abs() < 1e-15 {
                    break;
                }
            }
            (x, 2.0 / ((1.0 - x * x) * dp * dp))
        })
        .collect()
}

/// Unpolarized Fresnel reflectance of a dielectric interface (`eta` = int/ext, `cos_i`
/// signed: negative from inside).
pub(crate) fn fresnel_dielectric(cos_i: f64, eta: f64) -> f64 {
    let (eta_it, c) = if cos_i >= 0.0 { (eta, cos_i) } else { (1.0 / eta, -cos_i) };
    let sin_t2 = (1.0 - c * c) / (eta_it * eta_it);
    if sin_t2 >= 1.0 {
        return 1.0;
    }
    let ct = (1.0 - sin_t2).sqrt();
    let rs = (c - eta_it * ct) / (c + eta_it * ct);
    let rp = (eta_it * c - ct) / (eta_it * c + ct);
    0.5 * (rs * rs + rp * rp)
}

/// Smith's G1 of the distribution, Mitsuba's formulas (Beckmann: its rational fit).
pub(crate) fn smith_g1(dist: Distribution, alpha: f64, v: V3, m: V3) -> f64 {
    if dot(v, m) * v[2] <= 0.0 {
        return 0.0;
    }
    let xy = alpha * alpha * (v[0] * v[0] + v[1] * v[1]);
    if xy == 0.0 {
        return 1.0;
    }
    let t2 = xy / (v[2] * v[2]);
    match dist {
        Distribution::Ggx => 2.0 / (1.0 + (1.0 + t2).sqrt()),
        Distribution::Beckmann => {
            let a = 1.0 / t2.sqrt();
            if a >= 1.6 { 1.0 } else { (3.535 * a + 2.181 * a * a) / (1.0 + 2.276 * a + 2.577 * a * a) }
        }
    }
}

/// erf, to 1e-15 (series for small |x|, continued fraction beyond).
pub(crate) fn erf(x: f64) -> f64 {
    if x.abs() > 6.0 {
        return x.signum();
    }
    if x.abs() < 2.5 {
        let (mut sum, mut term, mut k) = (x, x, 0.0);
        while term.abs() > 1e-17 * sum.abs() {
            k += 1.0;
            term *= -x * x / k;
            sum += term / (2.0 * k + 1.0);
        }
        return 2.0 / PI.sqrt() * sum;
    }
    // erfc by Lentz's continued fraction.
    let z = x.abs();
    let mut f = z;
    let (mut c, mut d) = (z, 0.0);
    for n in 1..200 {
        let a = n as f64 * 0.5;
        d = z + a * d;
        d = if d == 0.0 { 1e-300 } else { 1.0 / d };
        c = z + a / c;
        let delta = c * d;
        f *= delta;
        if (delta - 1.0).abs() < 1e-16 {
            break;
        }
    }
    let erfc = (-z * z).exp() / (f * PI.sqrt());
    x.signum() * (1.0 - erfc)
}

/// Inverse of erf on (-1, 1): Giles' single-precision approximation refined by Newton steps.
pub(crate) fn erfinv(y: f64) -> f64 {
    let y = y.clamp(-1.0 + 1e-15, 1.0 - 1e-15);
    let mut w = -((1.0 - y) * (1.0 + y)).ln();
    let p = if w < 5.0 {
        w -= 2.5;
        [
            3.43273939e-07,
            -3.5233877e-06,
            -4.39150654e-06,
            0.00021858087,
            -0.00125372503,
            -0.00417768164,
            0.246640727,
            1.50140941,
        ]
        .iter()
        .fold(2.81022636e-08, |p, c| c + p * w)
    } else {
        w = w.sqrt() - 3.0;
        [
            0.000100950558,
            0.00134934322,
            -0.00367342844,
            0.00573950773,
            -0.0076224613,
            0.00943887047,
            1.00167406,
            2.83297682,
        ]
        .iter()
        .fold(-0.000200214257, |p, c| c + p * w)
    };
    let mut x = p * y;
    for _ in 0..4 {
        x -= (erf(x) - y) / (2.0 / PI.sqrt() * (-x * x).exp());
    }
    x
}

/// A visible normal for direction `wi` (upper hemisphere) from a point of the unit square.
pub(crate) fn sample_visible(dist: Distribution, alpha: f64, wi: V3, u: [f64; 2]) -> V3 {
    let v = normalize([alpha * wi[0], alpha * wi[1], wi[2]]);
    match dist {
        Distribution::Ggx => {
            // Heitz 2018, as in bsdf.wgsl.
            let len2 = v[0] * v[0] + v[1] * v[1];
            let t1 = if len2 > 0.0 { [-v[1] / len2.sqrt(), v[0] / len2.sqrt(), 0.0] } else { [1.0, 0.0, 0.0] };
            let t2 = [v[1] * t1[2] - v[2] * t1[1], v[2] * t1[0] - v[0] * t1[2], v[0] * t1[1] - v[1] * t1[0]];
            let r = u[0].sqrt();
            let phi = 2.0 * PI * u[1];
            let p1 = r * phi.cos();
            let s = 0.5 * (1.0 + v[2]);
            let p2 = (1.0 - s) * (1.0 - p1 * p1).max(0.0).sqrt() + s * r * phi.sin();
            let p3 = (1.0 - p1 * p1 - p2 * p2).max(0.0).sqrt();
            let n = [0, 1, 2].map(|k| p1 * t1[k] + p2 * t2[k] + p3 * v[k]);
            normalize([alpha * n[0], alpha * n[1], n[2].max(1e-9)])
        }
        Distribution::Beckmann => {
            let (slope_x, slope_y) = beckmann_slopes(v[2], u);
            let (sin_phi, cos_phi) = {
                let s = (v[0] * v[0] + v[1] * v[1]).sqrt();
                if s > 0.0 { (v[1] / s, v[0] / s) } else { (0.0, 1.0) }
            };
            let sx = (cos_phi * slope_x - sin_phi * slope_y) * alpha;
            let sy = (sin_phi * slope_x + cos_phi * slope_y) * alpha;
            normalize([-sx, -sy, 1.0])
        }
    }
}

/// Slopes of the Beckmann distribution (alpha 1) seen from cos θ: Mitsuba's inversion of the
/// visible-slope CDF, iterated to convergence.
fn beckmann_slopes(cos_theta: f64, u: [f64; 2]) -> (f64, f64) {
    let u = [u[0].clamp(1e-9, 1.0 - 1e-9), u[1].clamp(1e-9, 1.0 - 1e-9)];
    let tan_theta = (1.0 - cos_theta * cos_theta).max(0.0).sqrt() / cos_theta;
    let cot_theta = 1.0 / tan_theta;
    let maxval = erf(cot_theta);
    let inv_sqrt_pi = 1.0 / PI.sqrt();
    let target = u[0] * (1.0 + maxval + inv_sqrt_pi * tan_theta * (-cot_theta * cot_theta).exp());
    // The CDF in the erf domain, 1 + x + tanθ/√π exp(−erfinv(x)²), increases on [−1, maxval].
    let cdf = |x: f64| 1.0 + x + inv_sqrt_pi * tan_theta * (-erfinv(x).powi(2)).exp();
    let (mut lo, mut hi) = (-1.0, maxval);
    for _ in 0..80 {
        let mid = 0.5 * (lo + hi);
        if cdf(mid) < target {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    (erfinv(0.5 * (lo + hi)), erfinv(2.0 * u[1] - 1.0))
}

/// Fresnel reflectance and the refracted direction's cos θt (signed opposite to cos_i) of a
/// dielectric interface; `eta` = int/ext.
fn fresnel_refract(cos_i: f64, eta: f64) -> (f64, f64, f64) {
    let (eta_it, c) = if cos_i >= 0.0 { (eta, cos_i) } else { (1.0 / eta, -cos_i) };
    let sin_t2 = (1.0 - c * c) / (eta_it * eta_it);
    if sin_t2 >= 1.0 {
        return (1.0, 0.0, 1.0 / eta_it);
    }
    let ct = (1.0 - sin_t2).sqrt();
    (fresnel_dielectric(cos_i, eta), if cos_i >= 0.0 { -ct } else { ct }, 1.0 / eta_it)
}

/// The rough interface's directional reflectance (`transmit` false) or transmittance at
/// cos θi = `cos`: Mitsuba's `eval_reflectance` and `eval_transmittance`, Gauss–Legendre
/// quadrature over the visible-normal sample square (32² points when eta > 1, 128²
/// otherwise) of F · G1 of the reflected, or (1 − F) · G1 of the refracted, direction.
fn albedo(dist: Distribution, alpha: f64, eta: f64, cos: f64, transmit: bool) -> f64 {
    let wi = [(1.0 - cos * cos).max(0.0).sqrt(), 0.0, cos];
    let rule = gauss_legendre(if eta > 1.0 { 32 } else { 128 });
    let mut sum = 0.0;
    for &(x, wx) in &rule {
        for &(y, wy) in &rule {
            let m = sample_visible(dist, alpha, wi, [0.5 * x + 0.5, 0.5 * y + 0.5]);
            let d = dot(wi, m);
            let value = if transmit {
                let (f, cos_t, eta_ti) = fresnel_refract(d, eta);
                let k = d * eta_ti + cos_t;
                let wo = [0, 1, 2].map(|i| m[i] * k - wi[i] * eta_ti);
                if wo[2] * wi[2] >= 0.0 { 0.0 } else { (1.0 - f) * smith_g1(dist, alpha, wo, m) }
            } else {
                let wo = [0, 1, 2].map(|i| 2.0 * d * m[i] - wi[i]);
                if wo[2] <= 0.0 { 0.0 } else { fresnel_dielectric(d, eta) * smith_g1(dist, alpha, wo, m) }
            };
            sum += wx * wy * value;
        }
    }
    0.25 * sum
}

/// Tables of [`plastic_tables`] this process has computed, by distribution and the bits of alpha and
/// eta: each costs about a million quadrature points, and a dataset renders the same scene's
/// materials dozens of times. Cleared when it reaches `MAX_MEMO_TABLES` entries (a quarter of a MiB).
type PlasticKey = (Distribution, u32, u32);
type PlasticTables = ([f32; TABLE_SIZE], f32);
static PLASTIC_MEMO: LazyLock<Mutex<HashMap<PlasticKey, PlasticTables>>> = LazyLock::new(Default::default);
const MAX_MEMO_TABLES: usize = 1024;

/// Mitsuba 3's `roughplastic` tables at cos θ = max(10⁻⁶, i / 63): the coat's transmittance
/// (light that crosses the rough interface once), and the diffuse base's internal reflectance
/// 2 · mean(reflectance_inside(cos) · cos) over the same points; computed once per process for
/// each (distribution, alpha, eta).
pub(crate) fn plastic_tables(dist: Distribution, alpha: f32, eta: f32) -> PlasticTables {
    let key = (dist, alpha.to_bits(), eta.to_bits());
    // A poisoned lock only means another thread panicked while holding it; the map is still whole.
    let mut memo = PLASTIC_MEMO.lock().unwrap_or_else(|e| e.into_inner());
    if let Some(&t) = memo.get(&key) {
        return t;
    }
    drop(memo);
    let t = compute_plastic_tables(dist, alpha, eta);
    memo = PLASTIC_MEMO.lock().unwrap_or_else(|e| e.into_inner());
    if memo.len() >= MAX_MEMO_TABLES {
        memo.clear();
    }
    memo.insert(key, t);
    t
}

fn compute_plastic_tables(dist: Distribution, alpha: f32, eta: f32) -> PlasticTables {
    let (alpha, eta) = ((alpha as f64).max(1e-4), eta as f64);
    let cos = |i: usize| (i as f64 / (TABLE_SIZE - 1) as f64).max(1e-6);
    let external = std::array::from_fn(|i| albedo(dist, alpha, eta, cos(i), true) as f32);
    let internal: f64 = (0..TABLE_SIZE).map(|i| albedo(dist, alpha, 1.0 / eta, cos(i), false) * cos(i)).sum::<f64>()
        * 2.0
        / TABLE_SIZE as f64;
    (external, internal as f32)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn erf_and_its_inverse_agree_with_known_values() {
        // erf(0.5) and erf(2) to 12 digits (Abramowitz & Stegun, table 7.1).
        assert!((erf(0.5) - 0.520499877813).abs() < 1e-11);
        assert!((erf(2.0) - 0.995322265019).abs() < 1e-11);
        assert!((erf(3.0) - 0.999977909503).abs() < 1e-11);
        for y in [-0.999, -0.5, 0.0, 0.1, 0.9, 0.99999] {
            assert!((erf(erfinv(y)) - y).abs() < 1e-12, "erfinv({y})");
        }
    }

    /// A nearly smooth interface reflects and transmits as a smooth one (R + T = 1 with the
    /// Fresnel R); a rough one loses energy to the single-scattering model's shadowing, never
    /// gains it.
    #[test]
    fn a_nearly_smooth_coat_splits_light_by_fresnel() {
        for dist in [Distribution::Ggx, Distribution::Beckmann] {
            for cos in [0.3, 0.7, 1.0] {
                let r = albedo(dist, 1e-3, 1.5, cos, false);
                let t = albedo(dist, 1e-3, 1.5, cos, true);
                let f = fresnel_dielectric(cos, 1.5);
                assert!((r - f).abs() < 1e-3 && (t - (1.0 - f)).abs() < 1e-3, "{dist:?} cos {cos}: {r} {t}");
                let (r, t) = (albedo(dist, 0.5, 1.5, cos, false), albedo(dist, 0.5, 1.5, cos, true));
                assert!(r + t <= 1.0 + 1e-9 && r + t > 0.8, "{dist:?} cos {cos}: R {r} + T {t}");
            }
        }
    }
}
