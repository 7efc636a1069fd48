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
    // Weights are renormalized over the scales used: their overall scale does not matter, and the
    // weights of scales that do not fit are ignored.
    let a = scalar(&ms_ssim_weighted(&x, &y, &[0.3, 0.7])?);
    let b = scalar(&ms_ssim_weighted(&x, &y, &[3.0, 7.0, 100.0])?);
    assert!((a - b).abs() < 1e-6, "{a} vs {b}");
    let default = scalar(&ms_ssim(&x, &y)?);
    let first_two = scalar(&ms_ssim_weighted(&x, &y, &MS_SSIM_WEIGHTS[..2])?);
    assert_eq!(default, first_two);

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
        serde_json::to_string(&[Loss::L1, Loss::Mse, Loss::Ssim, Loss::MsSsim, Loss::Mix]).unwrap(),
        r#"["l1","mse","ssim","ms_ssim","mix"]"#
    );
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
