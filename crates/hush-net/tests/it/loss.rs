use candle_core::{DType, Device, Result, Tensor, Var};
use hush_net::Loss;
use hush_net::loss::{self, MS_SSIM_WEIGHTS, ms_ssim, ms_ssim_scales, ms_ssim_weighted, ssim};

use crate::det_tensor;

fn scalar(t: &Tensor) -> f64 {
    t.to_dtype(DType::F64).unwrap().to_scalar::<f64>().unwrap()
}

/// A direct (non-separable, two-pass) SSIM in f64: for each valid window position the local mean first,
/// then the local (co)variances around it. No cancellation, so it is the reference at any value range.
fn reference_ssim(x: &[f32], y: &[f32], n_planes: usize, h: usize, w: usize) -> f64 {
    let g: Vec<f64> = (0..11).map(|i| (-((i as f64 - 5.0).powi(2)) / (2.0 * 1.5 * 1.5)).exp()).collect();
    let gs: f64 = g.iter().sum();
    let g: Vec<f64> = g.iter().map(|v| v / gs).collect();
    let (c1, c2) = (0.01f64.powi(2), 0.03f64.powi(2));
    let mut total = 0.0;
    for p in 0..n_planes {
        let at = |img: &[f32], yy: usize, xx: usize| img[p * h * w + yy * w + xx] as f64;
        let mut sum = 0.0;
        for oy in 0..h - 10 {
            for ox in 0..w - 10 {
                let (mut mx, mut my) = (0.0, 0.0);
                for ky in 0..11 {
                    for kx in 0..11 {
                        let wgt = g[ky] * g[kx];
                        mx += wgt * at(x, oy + ky, ox + kx);
                        my += wgt * at(y, oy + ky, ox + kx);
                    }
                }
                let (mut vx, mut vy, mut cxy) = (0.0, 0.0, 0.0);
                for ky in 0..11 {
                    for kx in 0..11 {
                        let wgt = g[ky] * g[kx];
                        let (dx, dy) = (at(x, oy + ky, ox + kx) - mx, at(y, oy + ky, ox + kx) - my);
                        vx += wgt * dx * dx;
                        vy += wgt * dy * dy;
                        cxy += wgt * dx * dy;
                    }
                }
                let cs = (2.0 * cxy + c2) / (vx + vy + c2);
                sum += (2.0 * mx * my + c1) / (mx * mx + my * my + c1) * cs;
            }
        }
        total += sum / ((h - 10) * (w - 10)) as f64;
    }
    total / n_planes as f64
}

fn values(t: &Tensor) -> Vec<f32> {
    t.flatten_all().unwrap().to_vec1::<f32>().unwrap()
}

#[test]
fn ssim_of_identical_images_is_one() -> Result<()> {
    let x = det_tensor(&[1, 3, 16, 16], 0.0, 1.0, 1)?;
    assert!((scalar(&ssim(&x, &x)?) - 1.0).abs() < 1e-6);
    assert!((scalar(&ms_ssim(&x, &x)?) - 1.0).abs() < 1e-6);
    Ok(())
}

/// The separable custom filter and the SSIM formula agree with a direct f64 computation.
#[test]
fn ssim_matches_direct_reference() -> Result<()> {
    let (n, c, h, w) = (2, 3, 24, 19);
    let x = det_tensor(&[n, c, h, w], 0.0, 1.0, 2)?;
    let noise = det_tensor(&[n, c, h, w], -0.2, 0.2, 3)?;
    let y = (&x + &noise)?;
    let ours = scalar(&ssim(&x, &y)?);
    let reference = reference_ssim(&values(&x), &values(&y), n * c, h, w);
    assert!((ours - reference).abs() < 1e-5, "ssim {ours} vs reference {reference}");
    // The f64 path (candle's conv2d instead of the custom op) agrees too.
    let ours64 = scalar(&ssim(&x.to_dtype(DType::F64)?, &y.to_dtype(DType::F64)?)?);
    assert!((ours64 - reference).abs() < 1e-9, "f64 ssim {ours64} vs reference {reference}");
    Ok(())
}

/// anchors.md: in f32, E[x²] − E[x]² at 1e4 + noise gave SSIM −222 instead of ≈ −0.01. The shifted
/// moments stay within 1e-3 of the f64 reference; the naive formula misses that tolerance by far (so the
/// tolerance is one that can fail).
#[test]
fn ssim_is_stable_at_large_values() -> Result<()> {
    let (h, w) = (16, 16);
    let x = (det_tensor(&[1, 1, h, w], -1.0, 1.0, 4)? + 1e4)?;
    let y = (det_tensor(&[1, 1, h, w], -1.0, 1.0, 5)? + 1e4)?;
    let reference = reference_ssim(&values(&x), &values(&y), 1, h, w);
    let ours = scalar(&ssim(&x, &y)?);
    assert!((ours - reference).abs() < 1e-3, "ssim {ours} vs reference {reference}");

    // The naive single-pass formula, in f32, at one window position.
    let g: Vec<f32> = (0..11).map(|i| (-((i as f32 - 5.0).powi(2)) / 4.5).exp()).collect();
    let gs: f32 = g.iter().sum();
    let (xv, yv) = (values(&x), values(&y));
    let (mut mx, mut my, mut exx, mut eyy, mut exy) = (0f32, 0f32, 0f32, 0f32, 0f32);
    for ky in 0..11 {
        for kx in 0..11 {
            let wgt = g[ky] * g[kx] / (gs * gs);
            let (a, b) = (xv[ky * w + kx], yv[ky * w + kx]);
            mx += wgt * a;
            my += wgt * b;
            exx += wgt * a * a;
            eyy += wgt * b * b;
            exy += wgt * a * b;
        }
    }
    let cs = (2.0 * (exy - mx * my) + 9e-4) / ((exx - mx * mx) + (eyy - my * my) + 9e-4);
    let naive_ssim = (2.0 * mx * my + 1e-4) / (mx * mx + my * my + 1e-4) * cs;
    let naive_err = (naive_ssim as f64 - reference).abs();
    assert!(naive_err > 1e-3, "the naive formula was unexpectedly accurate ({naive_err})");
    Ok(())
}

#[test]
fn ssim_decreases_with_noise() -> Result<()> {
    let x = det_tensor(&[1, 3, 32, 32], 0.2, 0.8, 6)?;
    let noise = det_tensor(&[1, 3, 32, 32], -1.0, 1.0, 7)?;
    let mut last = 1.0;
    for sigma in [0.01, 0.05, 0.2] {
        let y = (&x + (&noise * sigma)?)?;
        let s = scalar(&ssim(&x, &y)?);
        let m = scalar(&ms_ssim(&x, &y)?);
        assert!(s < last, "ssim {s} at noise {sigma} is not below {last}");
        assert!(m < 1.0);
        last = s;
    }
    Ok(())
}

#[test]
fn ms_ssim_scale_counts() {
    for (side, scales) in [(176, 5), (175, 4), (512, 5), (88, 4), (87, 3), (22, 2), (21, 1), (11, 1), (10, 0)] {
        assert_eq!(ms_ssim_scales(side, 1000, 5), scales, "side {side}");
    }
    assert_eq!(ms_ssim_scales(1000, 1000, 3), 3);
}

/// Too small for 5 scales: the scales that fit, with renormalized weights.
#[test]
fn ms_ssim_falls_back_to_the_scales_that_fit() -> Result<()> {
    let x = det_tensor(&[1, 3, 24, 24], 0.0, 1.0, 8)?;
    let y = (&x + det_tensor(&[1, 3, 24, 24], -0.1, 0.1, 9)?)?;
    // 24 px: two scales (24, 12). Only the coarse one weighted: plain SSIM of the pooled images.
    let coarse = scalar(&ms_ssim_weighted(&x, &y, &[0.0, 1.0])?);
    let pooled = scalar(&ssim(&x.avg_pool2d(2)?, &y.avg_pool2d(2)?)?);
    assert!((coarse - pooled).abs() < 1e-6, "{coarse} vs {pooled}");
    // When scales are dropped, the weights of the others are renormalized: their overall scale does not
    // matter then, and the weights of scales that do not fit are ignored. When all fit they are used as
    // given (pytorch-msssim).
    let a = scalar(&ms_ssim_weighted(&x, &y, &[0.3, 0.7])?);
    let b = scalar(&ms_ssim_weighted(&x, &y, &[3.0, 7.0, 100.0])?);
    assert!((a - b).abs() < 1e-6, "{a} vs {b}");
    let default = scalar(&ms_ssim(&x, &y)?);
    let sum = MS_SSIM_WEIGHTS[0] + MS_SSIM_WEIGHTS[1];
    let first_two = scalar(&ms_ssim_weighted(&x, &y, &[MS_SSIM_WEIGHTS[0] / sum, MS_SSIM_WEIGHTS[1] / sum])?);
    assert!((default - first_two).abs() < 1e-7, "{default} vs {first_two}");

    // One scale (16 px): MS-SSIM is SSIM.
    let (x16, y16) = (x.narrow(2, 0, 16)?.narrow(3, 0, 16)?, y.narrow(2, 0, 16)?.narrow(3, 0, 16)?);
    assert!((scalar(&ms_ssim(&x16, &y16)?) - scalar(&ssim(&x16, &y16)?)).abs() < 1e-6);

    // Smaller than the window: a clear error.
    let (x10, y10) = (x.narrow(2, 0, 10)?, y.narrow(2, 0, 10)?);
    let err = ms_ssim(&x10, &y10).unwrap_err().to_string();
    assert!(err.contains("10x24") && err.contains("11x11"), "{err}");
    Ok(())
}

/// At 176 px all 5 scales are used: dropping the fifth weight changes the value.
#[test]
fn ms_ssim_uses_five_scales_when_they_fit() -> Result<()> {
    let x = det_tensor(&[1, 1, 176, 176], 0.0, 1.0, 10)?;
    let y = (&x + det_tensor(&[1, 1, 176, 176], -0.3, 0.3, 11)?)?;
    let five = scalar(&ms_ssim(&x, &y)?);
    let four = scalar(&ms_ssim_weighted(&x, &y, &MS_SSIM_WEIGHTS[..4])?);
    assert!((five - four).abs() > 1e-4, "{five} vs {four}");
    Ok(())
}

#[test]
fn shape_mismatch_names_both_shapes() -> Result<()> {
    let x = Tensor::zeros((1, 3, 16, 16), DType::F32, &Device::Cpu)?;
    let y = Tensor::zeros((1, 3, 16, 17), DType::F32, &Device::Cpu)?;
    for (name, err) in [
        ("l1", loss::l1(&x, &y)),
        ("mse", loss::mse(&x, &y)),
        ("ssim", ssim(&x, &y)),
        ("ms_ssim", ms_ssim(&x, &y)),
        ("mix", loss::mix(&x, &y)),
    ] {
        let err = err.unwrap_err().to_string();
        assert!(err.contains("[1, 3, 16, 16]") && err.contains("[1, 3, 16, 17]") && err.contains(name), "{err}");
    }
    let err = ssim(&x.flatten_all()?, &y.flatten_all()?.narrow(0, 0, 768)?).unwrap_err().to_string();
    assert!(err.contains("NCHW"), "{err}");
    Ok(())
}

#[test]
fn losses_have_the_documented_values() -> Result<()> {
    let x = det_tensor(&[2, 3, 24, 24], 0.0, 1.0, 12)?;
    let y = det_tensor(&[2, 3, 24, 24], 0.0, 1.0, 13)?;
    let l1 = scalar(&loss::l1(&x, &y)?);
    let mse = scalar(&loss::mse(&x, &y)?);
    let (xv, yv) = (values(&x), values(&y));
    let n = xv.len() as f64;
    let l1_ref = xv.iter().zip(&yv).map(|(a, b)| (a - b).abs() as f64).sum::<f64>() / n;
    let mse_ref = xv.iter().zip(&yv).map(|(a, b)| ((a - b) as f64).powi(2)).sum::<f64>() / n;
    assert!((l1 - l1_ref).abs() < 1e-6 && (mse - mse_ref).abs() < 1e-6);
    let ms = scalar(&ms_ssim(&x, &y)?);
    let mix = scalar(&loss::mix(&x, &y)?);
    assert!((mix - (0.16 * l1 + 0.84 * (1.0 - ms))).abs() < 1e-6);
    assert!((scalar(&Loss::Mix.compute(&x, &y)?) - mix).abs() < 1e-7);
    assert!((scalar(&Loss::Ssim.compute(&x, &y)?) - (1.0 - scalar(&ssim(&x, &y)?))).abs() < 1e-7);
    assert!((scalar(&Loss::MsSsim.compute(&x, &y)?) - (1.0 - ms)).abs() < 1e-7);
    assert_eq!(
        serde_json::to_string(&Loss::ALL).unwrap(),
        r#"["l1","mse","ssim","ms_ssim","mix","mape","smape","l1_grad","log_mse"]"#
    );
    for l in Loss::ALL {
        assert_eq!(serde_json::to_string(&l).unwrap(), format!("\"{}\"", l.name()));
        assert_eq!(Loss::parse(l.name()), Some(l));
    }
    assert_eq!(Loss::parse("l1_msssim"), Some(Loss::Mix));
    assert_eq!(Loss::parse("l2"), Some(Loss::Mse));
    assert_eq!(Loss::parse("msssim"), Some(Loss::MsSsim));
    assert_eq!(Loss::parse("lpips"), None);
    Ok(())
}

/// Inputs made from raw radiance 0, 1e-8 and 1e6 through the color pipeline (so 0, tiny and the clamp at
/// 1), against targets including an anti-correlated one that drives contrast-structure below 0 (the ReLU
/// before the power): every loss has finite gradients, not all zero.
#[test]
fn gradients_are_finite_on_extreme_inputs() -> Result<()> {
    let (h, w) = (24, 24);
    let raw: Vec<f32> = (0..3 * h * w).map(|i| [0.0, 1e-8, 1e6][(i / 7) % 3]).collect();
    let prepared = hush_net::prepare_color(&raw, 1.0, hush_net::transfer::Transfer::Pu);
    let x0 = hush_net::hwc_to_nchw(&prepared, w, h, 3, &Device::Cpu)?;
    let zeros = x0.zeros_like()?;
    let anti = x0.affine(-1.0, 1.0)?;
    for target in [&x0, &zeros, &anti] {
        for start in [&x0, &zeros] {
            for l in [Loss::L1, Loss::Mse, Loss::Ssim, Loss::MsSsim, Loss::Mix] {
                let var = Var::from_tensor(start)?;
                let value = l.compute(var.as_tensor(), target)?;
                assert!(scalar(&value).is_finite(), "{l:?}: loss is not finite");
                let grads = value.backward()?;
                let g = values(grads.get(&var).expect("gradient"));
                assert!(g.iter().all(|v| v.is_finite()), "{l:?}: non-finite gradient");
            }
        }
    }
    // Gradients do flow: a noisy copy gets a non-zero gradient from each loss. (Against the
    // anti-correlated target MS-SSIM's gradient is exactly 0: the ReLU clamps a negative contrast term.)
    let noisy = (&x0 + crate::det_tensor(&[1, 3, h, w], -0.1, 0.1, 16)?)?;
    for l in [Loss::L1, Loss::Mse, Loss::Ssim, Loss::MsSsim, Loss::Mix] {
        let var = Var::from_tensor(&noisy)?;
        let grads = l.compute(var.as_tensor(), &x0)?.backward()?;
        assert!(values(grads.get(&var).unwrap()).iter().any(|v| *v != 0.0), "{l:?}: zero gradient");
    }
    Ok(())
}

/// Only a network's output goes below 0 (targets are in the transfer's [0, 1]). A negated image is not
/// similar: with the luminance term unclamped, its negative luminance times its negative contrast-structure
/// made SSIM(−y, y) ≈ 1, an optimum that drove a channel of training runs below 0 for good.
#[test]
fn a_negated_image_is_not_similar() -> Result<()> {
    let y = det_tensor(&[1, 3, 32, 32], 0.2, 0.8, 21)?;
    let s = scalar(&ssim(&y.neg()?, &y)?);
    // The negation's local luminance term is C1 / (μ1² + μ2² + C1) ≈ 4e-4 here; 0.01 is far from the ≈ 1 of
    // the unclamped formula.
    assert!(s < 0.01, "SSIM(-y, y) = {s}");
    Ok(())
}

/// A channel below 0 that follows the target's structure (what a network with a negative output bias gives
/// at initialization) gets an MS-SSIM gradient that raises it. Unclamped, its coarsest scale's SSIM was
/// negative, MS-SSIM's clamp made the channel's product 0 with a zero gradient, and the channel stayed dead
/// (the collapsed `ann` and `msssim` runs of the small sweep).
#[test]
fn ms_ssim_raises_a_channel_below_zero() -> Result<()> {
    // 64² as the training crops: 3 scales.
    let y = det_tensor(&[1, 1, 64, 64], 0.2, 0.8, 22)?;
    let var = Var::from_tensor(&y.affine(0.5, -0.5)?)?;
    for l in [Loss::MsSsim, Loss::Mix] {
        let grads = l.compute(var.as_tensor(), &y)?.backward()?;
        let g = values(grads.get(&var).expect("gradient"));
        let sum: f64 = g.iter().map(|&v| v as f64).sum();
        // The loss falls as the output rises: the summed gradient is negative (exactly 0 before the fix).
        assert!(sum < 0.0, "{l:?}: summed gradient {sum}");
    }
    Ok(())
}

/// The analytic gradient of SSIM (custom f32 filter with its hand-written backward) matches the f64 path
/// (candle's conv2d) and central finite differences.
#[test]
fn ssim_gradient_matches_finite_differences() -> Result<()> {
    let (h, w) = (14, 13);
    let x = det_tensor(&[1, 2, h, w], 0.0, 1.0, 14)?;
    let y = (&x + det_tensor(&[1, 2, h, w], -0.2, 0.2, 15)?)?;
    let grad_of = |x: &Tensor, y: &Tensor| -> Result<Vec<f64>> {
        let var = Var::from_tensor(x)?;
        let g = ms_ssim(var.as_tensor(), y)?.backward()?;
        g.get(&var).unwrap().to_dtype(DType::F64)?.flatten_all()?.to_vec1::<f64>()
    };
    let g32 = grad_of(&x, &y)?;
    let (x64, y64) = (x.to_dtype(DType::F64)?, y.to_dtype(DType::F64)?);
    let g64 = grad_of(&x64, &y64)?;
    let scale = g64.iter().fold(0f64, |m, v| m.max(v.abs()));
    assert!(scale > 1e-4, "the gradient should not vanish here");
    for (a, b) in g32.iter().zip(&g64) {
        assert!((a - b).abs() < 1e-3 * scale, "f32 gradient {a} vs f64 {b}");
    }
    let xv = x64.flatten_all()?.to_vec1::<f64>()?;
    let eps = 1e-6;
    for i in [0, 17, 95, 200, 2 * h * w - 1] {
        let mut plus = xv.clone();
        plus[i] += eps;
        let mut minus = xv.clone();
        minus[i] -= eps;
        let f = |v: Vec<f64>| -> Result<f64> {
            let t = Tensor::from_vec(v, (1, 2, h, w), &Device::Cpu)?;
            Ok(scalar(&ms_ssim(&t, &y64)?))
        };
        let numeric = (f(plus)? - f(minus)?) / (2.0 * eps);
        assert!((numeric - g64[i]).abs() < 1e-6 + 1e-4 * numeric.abs(), "element {i}: {numeric} vs {}", g64[i]);
    }
    Ok(())
}

/// `log_mse` by hand: two images whose MSEs differ a hundredfold count alike, as in a mean PSNR.
#[test]
fn log_mse_is_the_mean_of_each_images_log_mse() -> Result<()> {
    let dev = Device::Cpu;
    // Image 0 is off by 0.1 everywhere (MSE 1e-2), image 1 by 0.01 (MSE 1e-4).
    let y = Tensor::zeros((2, 3, 4, 4), candle_core::DType::F32, &dev)?;
    let x = Tensor::cat(&[(y.narrow(0, 0, 1)? + 0.1)?, (y.narrow(0, 1, 1)? + 0.01)?], 0)?;
    let expected = ((1.0f64 + 1e-2 / 1e-5).ln() + (1.0f64 + 1e-4 / 1e-5).ln()) / 2.0;
    assert!((scalar(&Loss::LogMse.compute(&x, &y)?) - expected).abs() < 1e-4 * expected);
    // Each image's gradient is its squared error's scaled by 1 / (MSE_i + 1e-5): per pixel 2·d / (n·(MSE_i + floor))
    // halved by the batch mean.
    let var = Var::from_tensor(&x)?;
    let g = Loss::LogMse.compute(var.as_tensor(), &y)?.backward()?;
    let g = values(g.get(&var).expect("gradient"));
    let n = 48.0;
    let (g0, g1) = (2.0 * 0.1 / (n * (1e-2 + 1e-5)) / 2.0, 2.0 * 0.01 / (n * (1e-4 + 1e-5)) / 2.0);
    assert!(
        (f64::from(g[0]) - g0).abs() < 1e-3 * g0 && (f64::from(g[48]) - g1).abs() < 1e-3 * g1,
        "{} {}",
        g[0],
        g[48]
    );
    assert!(Loss::LogMse.compute(&x.flatten_all()?, &y.flatten_all()?).is_err(), "not NCHW");
    Ok(())
}

/// OIDN's MAPE, SMAPE and `l1_grad` (`training/loss.py`, `training/util.py`), computed by hand.
#[test]
fn mape_smape_and_l1_grad_by_hand() -> Result<()> {
    let dev = Device::Cpu;
    // One 2×2 image, one channel: x = [[1, 2], [3, 5]], y = [[1, 0], [2, 2]].
    let x = Tensor::new(&[1f32, 2.0, 3.0, 5.0], &dev)?.reshape((1, 1, 2, 2))?;
    let y = Tensor::new(&[1f32, 0.0, 2.0, 2.0], &dev)?.reshape((1, 1, 2, 2))?;
    let mape = (0.0 / 1.01 + 2.0 / 0.01 + 1.0 / 2.01 + 3.0 / 2.01) / 4.0;
    let smape = (0.0 / 2.01 + 2.0 / 2.01 + 1.0 / 5.01 + 3.0 / 7.01) / 4.0;
    assert!((scalar(&loss::mape(&x, &y)?) - mape).abs() < 1e-4 * mape, "{}", scalar(&loss::mape(&x, &y)?));
    assert!((scalar(&loss::smape(&x, &y)?) - smape).abs() < 1e-6);
    assert!((scalar(&Loss::Smape.compute(&x, &y)?) - smape).abs() < 1e-6);
    // Forward differences on the 1×1 grid: x: dy = 2, dx = 1; y: dy = 1, dx = −1. Gradient loss
    // (|2 − 1| + |1 − (−1)|) / 2 = 1.5; L1 = (0 + 2 + 1 + 3) / 4 = 1.5; l1_grad = 0.5·1.5 + 0.5·1.5.
    assert!((scalar(&loss::gradient_l1(&x, &y)?) - 1.5).abs() < 1e-6);
    assert!((scalar(&Loss::L1Grad.compute(&x, &y)?) - 1.5).abs() < 1e-6);
    // A constant offset has no gradient error, only L1.
    let x = det_tensor(&[2, 3, 8, 9], 0.0, 1.0, 30)?;
    assert!(scalar(&loss::gradient_l1(&(&x + 0.25)?, &x)?) < 1e-6);
    assert!((scalar(&loss::l1_grad(&(&x + 0.25)?, &x)?) - 0.125).abs() < 1e-6);
    // Shapes are checked; a single row has no vertical difference.
    let e = loss::gradient_l1(&x.narrow(2, 0, 1)?, &x.narrow(2, 0, 1)?).unwrap_err().to_string();
    assert!(e.contains("2x2"), "{e}");
    let e = loss::mape(&x, &x.narrow(3, 0, 8)?).unwrap_err().to_string();
    assert!(e.contains("mape") && e.contains("[2, 3, 8, 9]") && e.contains("[2, 3, 8, 8]"), "{e}");
    Ok(())
}

/// 32-bit integer hash shared with `fixtures/ssim_reference.py`.
fn hash(i: u64) -> u64 {
    let mut x = i.wrapping_mul(2_654_435_761) & 0xFFFF_FFFF;
    x ^= x >> 15;
    x = x.wrapping_mul(2_246_822_519) & 0xFFFF_FFFF;
    x ^= x >> 13;
    x
}

/// The images of `fixtures/ssim_reference.py`, bit for bit (integers over 256).
fn reference_images() -> Result<(Tensor, Tensor)> {
    let (n, c, h, w) = (2u64, 3u64, 192u64, 176u64);
    let (mut a, mut b) = (Vec::new(), Vec::new());
    for ni in 0..n {
        for ci in 0..c {
            for y in 0..h {
                for x in 0..w {
                    let i = ((ni * c + ci) * h + y) * w + x;
                    let ai = (3 * x * x + 7 * y + 50 * ci + 37 * ni + hash(i) % 16) % 256;
                    let bi = (ai as i64 * 230 / 256 + 8 + (hash(i + 1_000_003) % 81) as i64 - 40).clamp(0, 255);
                    a.push(ai as f32 / 256.0);
                    b.push(bi as f32 / 256.0);
                }
            }
        }
    }
    let shape = (n as usize, c as usize, h as usize, w as usize);
    Ok((Tensor::from_vec(a, shape, &Device::Cpu)?, Tensor::from_vec(b, shape, &Device::Cpu)?))
}

fn reference_json() -> serde_json::Value {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/it/fixtures/ssim_reference.json");
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// SSIM equals scikit-image's and MS-SSIM pytorch-msssim's (both computed in f64 by
/// `fixtures/ssim_reference.py`) to 1e-5 on the same 2×3×192×176 images; hush computes in f32, whose
/// rounding over the 11×11 window sums is ~1e-7.
#[test]
fn ssim_and_ms_ssim_match_scikit_image_and_pytorch_msssim() -> Result<()> {
    let expected = reference_json();
    let (a, b) = reference_images()?;
    // The same images as in Python.
    assert_eq!(scalar(&a.to_dtype(DType::F64)?.sum_all()?), expected["sum_a"].as_f64().unwrap());
    assert_eq!(scalar(&b.to_dtype(DType::F64)?.sum_all()?), expected["sum_b"].as_f64().unwrap());
    for (name, ours) in [
        ("ssim_skimage", scalar(&ssim(&b, &a)?)),
        ("ms_ssim_pytorch_msssim", scalar(&ms_ssim(&b, &a)?)),
        ("ms_ssim_pytorch_msssim_weights_0.2", scalar(&ms_ssim_weighted(&b, &a, &[0.2; 5])?)),
    ] {
        let theirs = expected[name].as_f64().unwrap();
        eprintln!("{name}: hush {ours:.9}, reference {theirs:.9}, difference {:.1e}", ours - theirs);
        assert!((ours - theirs).abs() < 1e-5, "{name}: hush {ours} vs {theirs}");
    }
    Ok(())
}

/// Raw radiance images that stress the pipeline: constant, black, 1e-8 and 1e6 everywhere, NaN and ±Inf
/// pixels, a single 1e6 firefly (and a 1e38 one) on a smooth image.
fn stiff_images(w: usize, h: usize) -> Vec<(&'static str, Vec<f32>)> {
    let smooth: Vec<f32> = (0..w * h * 3).map(|i| 0.05 + 0.5 * ((i / 3) % w) as f32 / w as f32).collect();
    let with = |at: &[(usize, f32)]| {
        let mut v = smooth.clone();
        for &(p, value) in at {
            v[3 * p..3 * p + 3].fill(value);
        }
        v
    };
    vec![
        ("smooth", smooth.clone()),
        ("constant", vec![0.5; w * h * 3]),
        ("black", vec![0.0; w * h * 3]),
        ("1e-8", vec![1e-8; w * h * 3]),
        ("1e6", vec![1e6; w * h * 3]),
        ("nan", with(&[(5, f32::NAN), (w * h / 2, f32::NAN)])),
        ("+inf", with(&[(7, f32::INFINITY)])),
        ("-inf", with(&[(9, f32::NEG_INFINITY)])),
        ("firefly 1e6", with(&[(w * h / 2 + 3, 1e6)])),
        ("firefly 1e38", with(&[(w * 3 + 3, 1e38)])),
    ]
}

/// Every loss and its gradient stay finite on every stiff image, at exposure 1 and at the image's
/// autoexposure, as prediction against the smooth target and as target of a noisy prediction. 32 px
/// gives MS-SSIM 2 scales; 176 px (all 5) is checked for the firefly.
#[test]
fn stiff_inputs_give_finite_losses_and_gradients() -> Result<()> {
    use hush_net::transfer::{Transfer, autoexposure};
    for (w, h) in [(32, 32), (176, 176)] {
        let images = stiff_images(w, h);
        let images: Vec<_> =
            if w == 32 { images } else { images.into_iter().filter(|(n, _)| n.starts_with("firefly")).collect() };
        let target_raw = &stiff_images(w, h)[0].1;
        let noise = det_tensor(&[1, 3, h, w], -0.05, 0.05, 31)?;
        for (name, raw) in &images {
            for exposure in [1.0, autoexposure(raw, w, h)] {
                assert!(exposure.is_finite() && exposure > 0.0, "{name}: exposure {exposure}");
                let prep = |v: &[f32]| {
                    hush_net::hwc_to_nchw(&hush_net::prepare_color(v, exposure, Transfer::Pu), w, h, 3, &Device::Cpu)
                };
                let (x, target) = (prep(raw)?, prep(target_raw)?);
                assert!(values(&x).iter().all(|v| v.is_finite() && (0.0..=1.0).contains(v)), "{name}");
                for l in Loss::ALL {
                    for (pred, tgt) in [(&x, &target), (&(&x + &noise)?, &x), (&x, &x)] {
                        let var = Var::from_tensor(pred)?;
                        let value = l.compute(var.as_tensor(), tgt)?;
                        assert!(scalar(&value).is_finite(), "{name} {l:?}: loss {}", scalar(&value));
                        let g = values(value.backward()?.get(&var).expect("gradient"));
                        assert!(g.iter().all(|v| v.is_finite()), "{name} {l:?}: non-finite gradient");
                    }
                }
            }
        }
    }
    Ok(())
}

/// The sanitization policy at inference: a NaN, ±Inf or 1e38 pixel never blanks the image. The denoised
/// image is finite everywhere, and for NaN/±Inf it is exactly the image denoised with those samples set
/// to 0.
#[test]
fn non_finite_input_never_blanks_the_image() -> Result<()> {
    use candle_nn::{VarBuilder, VarMap};
    use hush_net::{InputFeatures, ModelInfo, UNet, UNetConfig, denoise, init_weights, transfer::Transfer};
    let (w, h) = (48, 32);
    let varmap = VarMap::new();
    let cfg = UNetConfig { width: 0.25, ..UNetConfig::oidn(3) };
    let info = ModelInfo { net: cfg.clone().into(), features: InputFeatures::default(), transfer: Transfer::Pu };
    let net = UNet::new(VarBuilder::from_varmap(&varmap, DType::F32, &Device::Cpu), &cfg)?;
    init_weights(&varmap, 17)?;
    let images = stiff_images(w, h);
    let clean = denoise(&net, &info, w, h, &images[0].1, &[])?;
    assert!(clean.iter().any(|v| *v > 0.0), "the test network outputs black");
    for (name, raw) in &images {
        let out = denoise(&net, &info, w, h, raw, &[])?;
        assert!(out.iter().all(|v| v.is_finite()), "{name}: non-finite output");
        if raw.iter().any(|v| !v.is_finite()) {
            let zeroed: Vec<f32> = raw.iter().map(|&v| if v.is_finite() { v } else { 0.0 }).collect();
            assert_eq!(out, denoise(&net, &info, w, h, &zeroed, &[])?, "{name}");
        }
    }
    // The 1e38 firefly sits at (3, 3); columns 40.. are > 32 px away. They are not blanked (OIDN 2.5.1
    // returns black there). Their values are not the clean ones either: on an image of 3 × 2 autoexposure
    // bins, one bin of mean 1e38 / 256 legitimately lowers the geometric-mean exposure by 2^39, as OIDN's
    // formula says, and this untrained network is not scale-invariant.
    let firefly = denoise(&net, &info, w, h, &images[9].1, &[])?;
    let far: Vec<f32> = (0..h).flat_map(|y| (40..w).map(move |x| (y * w + x) * 3)).map(|i| firefly[i]).collect();
    assert!(far.iter().filter(|v| **v > 0.0).count() > far.len() / 2, "the far side was blanked");
    Ok(())
}

/// MSE in the tonemapped loss space, of PU-encoded images, is the MSE of their tonemapped linear values
/// (what hush eval's PSNR is computed from), up to f32 rounding through the PU round trip (1e-4 relative).
#[test]
fn tonemapped_mse_is_the_metrics_mse() -> Result<()> {
    use hush_net::LossSpace;
    use hush_net::transfer::{Transfer, display, pu_forward};
    let (n, c, h, w) = (1, 3, 4, 5);
    let a: Vec<f32> = (0..n * c * h * w).map(|i| ((i * 37 % 23) as f32 / 4.0).powi(2) / 10.0).collect();
    let b: Vec<f32> = (0..n * c * h * w).map(|i| ((i * 11 % 19) as f32 / 3.0).powi(2) / 10.0).collect();
    let expected = a.iter().zip(&b).map(|(x, y)| (display(*x) - display(*y)).powi(2)).sum::<f64>() / a.len() as f64;
    let encode =
        |v: &[f32]| Tensor::from_vec(v.iter().map(|&x| pu_forward(x)).collect::<Vec<_>>(), (n, c, h, w), &Device::Cpu);
    let got = scalar(&LossSpace::Tonemapped.compute(Loss::Mse, Transfer::Pu, &encode(&a)?, &encode(&b)?)?);
    assert!((got - expected).abs() < 1e-4 * expected, "tonemapped MSE {got}, metric's {expected}");
    let plain = scalar(&LossSpace::Transfer.compute(Loss::Mse, Transfer::Pu, &encode(&a)?, &encode(&b)?)?);
    assert!((plain - expected).abs() > 1e-3 * expected, "the transfer space should differ: {plain} vs {expected}");
    Ok(())
}

/// The colour-mean term sees image means only: pixels moved around inside an image cost nothing; a channel
/// 2 % brighter on average costs exactly its squared relative share, `(0.02·m / (m + floor))²`, divided among
/// the channels and images it is averaged over.
#[test]
fn color_mean_sees_each_channels_image_mean_only() -> Result<()> {
    use hush_net::loss::{COLOR_MEAN_FLOOR, color_mean};
    let dev = Device::Cpu;
    let (n, c, h, w) = (2usize, 3usize, 4usize, 5usize);
    let y: Vec<f32> = (0..n * c * h * w).map(|i| 0.1 + 0.8 * ((i * 37 % 101) as f32 / 101.0)).collect();
    let target = Tensor::from_vec(y.clone(), (n, c, h, w), &dev)?;
    // Each plane reversed: every pixel changes, no mean does.
    let reversed: Vec<f32> = y.chunks(h * w).flat_map(|p| p.iter().rev().copied().collect::<Vec<_>>()).collect();
    let moved = Tensor::from_vec(reversed, (n, c, h, w), &dev)?;
    assert!(scalar(&(&moved - &target)?.abs()?.mean_all()?) > 0.1, "the test image must differ per pixel");
    assert!(scalar(&color_mean(&moved, &target)?) < 1e-12);
    // Image 1's green plane 2 % brighter.
    let mut brighter = y.clone();
    let plane = (c + 1) * h * w; // image 1, channel 1
    let before: f64 = brighter[plane..plane + h * w].iter().map(|&v| v as f64).sum::<f64>() / (h * w) as f64;
    brighter[plane..plane + h * w].iter_mut().for_each(|v| *v *= 1.02);
    let got = scalar(&color_mean(&Tensor::from_vec(brighter, (n, c, h, w), &dev)?, &target)?);
    let want = (0.02 * before / (before + COLOR_MEAN_FLOOR)).powi(2) / (n * c) as f64;
    assert!((got - want).abs() < 1e-4 * want, "got {got}, want {want}");
    Ok(())
}
