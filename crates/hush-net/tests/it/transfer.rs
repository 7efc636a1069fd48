use candle_core::{Device, Result, Tensor};
use hush_net::transfer::{
    HDR_Y_MAX, Transfer, autoexposure, log_forward, log_inverse, pu_forward, pu_inverse, srgb_forward, srgb_inverse,
};

const GRID: [f32; 12] = [0.0, 1e-8, 1e-6, 1.5e-6, 1e-4, 0.01, 0.0322, 0.05, 1.0, 100.0, 5000.0, 65504.0];

fn rel_err(a: f32, b: f32) -> f32 {
    (a - b).abs() / b.abs().max(1e-12)
}

#[test]
fn pu_is_normalized_monotonic_and_invertible() {
    assert!((pu_forward(HDR_Y_MAX) - 1.0).abs() < 1e-6);
    assert_eq!(pu_forward(0.0), 0.0);
    for pair in GRID.windows(2) {
        assert!(pu_forward(pair[0]) < pu_forward(pair[1]), "not increasing at {pair:?}");
    }
    for y in GRID {
        let back = pu_inverse(pu_forward(y));
        assert!(rel_err(back, y) < 1e-4 || (back - y).abs() < 1e-12, "pu round trip {y} -> {back}");
    }
    // The fit is (nearly) continuous at its two breakpoints (OIDN's PU_Y0, PU_Y1).
    for y0 in [1.579_457_6e-6_f32, 3.220_876_3e-2] {
        let (lo, hi) = (pu_forward(y0 * (1.0 - 1e-4)), pu_forward(y0 * (1.0 + 1e-4)));
        assert!((hi - lo).abs() < 1e-3, "jump at {y0}: {lo} -> {hi}");
    }
}

/// Spot values of the PU curve computed from the constants of OIDN's training/color.py in Python:
/// `pu_forward(y) * PU_X_SCALE` for y = 1 and 100.
#[test]
fn pu_matches_oidn_values() {
    // (0.192653254 * ln(1 + 0.00626026094) + 0.998620152) / 3.1351190358395673
    assert!((pu_forward(1.0) - 0.3189105).abs() < 1e-6, "{}", pu_forward(1.0));
    // (0.192653254 * ln(100.00626026094) + 0.998620152) / 3.1351190358395673
    assert!((pu_forward(100.0) - 0.6015189).abs() < 1e-6, "{}", pu_forward(100.0));
}

#[test]
fn log_and_srgb_round_trip() {
    assert!((log_forward(HDR_Y_MAX) - 1.0).abs() < 1e-6);
    assert!((srgb_forward(1.0) - 1.0).abs() < 1e-6);
    for y in GRID {
        assert!(rel_err(log_inverse(log_forward(y)), y) < 1e-4 || y < 1e-6, "log {y}");
    }
    for y in [0.0f32, 0.001, 0.0031308, 0.01, 0.5, 1.0] {
        assert!((srgb_inverse(srgb_forward(y)) - y).abs() < 1e-6, "srgb {y}");
    }
}

/// The tensor versions agree with the scalar ones.
#[test]
fn tensor_transfers_match_scalar_ones() -> Result<()> {
    let t = Tensor::new(&GRID, &Device::Cpu)?;
    for tf in [Transfer::Linear, Transfer::Srgb, Transfer::Pu, Transfer::Log] {
        let fwd = tf.forward_tensor(&t)?.to_vec1::<f32>()?;
        for (y, v) in GRID.iter().zip(&fwd) {
            assert!(
                (tf.forward(*y) - v).abs() <= 2e-6 * v.abs().max(1.0),
                "{tf:?} forward {y}: {v} vs {}",
                tf.forward(*y)
            );
        }
        let inv = tf.inverse_tensor(&Tensor::new(fwd.as_slice(), &Device::Cpu)?)?.to_vec1::<f32>()?;
        for (x, v) in fwd.iter().zip(&inv) {
            let s = tf.inverse(*x);
            assert!((s - v).abs() <= 1e-4 * s.abs().max(1e-3), "{tf:?} inverse {x}: {v} vs {s}");
        }
    }
    Ok(())
}

fn constant_image(w: usize, h: usize, rgb: [f32; 3]) -> Vec<f32> {
    (0..w * h).flat_map(|_| rgb).collect()
}

#[test]
fn autoexposure_follows_oidn() {
    // Luminance weights sum to 1, so grey 2.0 has luminance 2 and exposure 0.18 / 2.
    assert!((autoexposure(&constant_image(40, 24, [2.0; 3]), 40, 24) - 0.09).abs() < 1e-6);
    // Black (or all below 1e-8): 1.
    assert_eq!(autoexposure(&constant_image(16, 16, [0.0; 3]), 16, 16), 1.0);
    assert_eq!(autoexposure(&constant_image(16, 16, [1e-9; 3]), 16, 16), 1.0);
    // 32×32, left half luminance 1, right half 4: four 16×16 bins, mean log2 = 1, exposure 0.09.
    let img: Vec<f32> = (0..32 * 32).flat_map(|i| if i % 32 < 16 { [1.0; 3] } else { [4.0; 3] }).collect();
    assert!((autoexposure(&img, 32, 32) - 0.09).abs() < 1e-6);
    // Bins average before the log: a 16×16 image with one pixel of 256 has bin mean 1 → 0.18.
    let mut spot = constant_image(16, 16, [0.0; 3]);
    spot[..3].copy_from_slice(&[256.0; 3]);
    assert!((autoexposure(&spot, 16, 16) - 0.18).abs() < 1e-6);
    // NaN, -Inf, +Inf and negatives count as 0.
    for bad in [f32::NAN, f32::NEG_INFINITY, f32::INFINITY, -5.0] {
        let mut img = spot.clone();
        img[3..6].copy_from_slice(&[bad; 3]);
        assert!((autoexposure(&img, 16, 16) - 0.18).abs() < 1e-6, "{bad}");
    }
    // 20 px: ceil(20/16) = 2 bins of 10 per side, each mean 1 except the one holding the spot.
    let mut img = constant_image(20, 20, [1.0; 3]);
    img[..3].copy_from_slice(&[101.0; 3]); // bin (0,0): mean 2
    let expected = 0.18 / (0.25f64 * 1.0).exp2(); // log2 means: 1, 0, 0, 0
    assert!((autoexposure(&img, 20, 20) as f64 - expected).abs() < 1e-6);
}

/// The differentiable evaluation transform that `--loss-space tonemapped` trains through is the metrics'
/// `display` between 0 and the white point (1e-5: f32 against f64), continues linearly below 0 and keeps
/// rising above the white point, and has a finite, positive gradient everywhere a network output can land.
#[test]
fn display_tensor_is_the_evaluation_transform_with_a_gradient_everywhere() -> Result<()> {
    use hush_net::transfer::{display, display_tensor};
    let dev = Device::Cpu;
    let inside = [0.0f32, 1e-5, 1e-3, 0.01, 0.18, 0.5, 1.0, 3.0, 6.0];
    let out = display_tensor(&Tensor::new(&inside[..], &dev)?)?.to_vec1::<f32>()?;
    for (x, d) in inside.iter().zip(&out) {
        assert!((f64::from(*d) - display(*x)).abs() < 1e-5, "display_tensor({x}) = {d}, display = {}", display(*x));
    }
    // Below 0: the line of the slope at 0, continuous there.
    let near = display_tensor(&Tensor::new(&[-1e-4f32, 1e-4, -0.5, -1.0][..], &dev)?)?.to_vec1::<f32>()?;
    assert!((near[0] + near[1]).abs() < 1e-6, "not continuous and odd-linear at 0: {near:?}");
    assert!((near[3] - 2.0 * near[2]).abs() < 1e-5 && near[3] < 0.0, "not linear below 0: {near:?}");
    // Above the white point (11.2 / 1.758141 ≈ 6.37): still increasing, where `display` is flat at 1.
    let high = display_tensor(&Tensor::new(&[6.0f32, 20.0, 1e3, 1e6][..], &dev)?)?.to_vec1::<f32>()?;
    assert!(high.windows(2).all(|w| w[0] < w[1]) && high[3] < 1.1, "{high:?}");
    assert_eq!(display(20.0), display(1e3));
    // Gradients: finite and positive on every side.
    let grid = [-1.0f32, -1e-3, 0.0, 1e-6, 0.1, 1.0, 6.0, 100.0, 1e6];
    let x = candle_core::Var::new(&grid[..], &dev)?;
    let grads = display_tensor(x.as_tensor())?.sum_all()?.backward()?;
    let g = grads.get(x.as_tensor()).expect("a gradient").to_vec1::<f32>()?;
    for (x, g) in grid.iter().zip(&g) {
        assert!(g.is_finite() && *g > 0.0, "gradient {g} at {x}");
    }
    Ok(())
}
