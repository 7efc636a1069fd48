use candle_core::{DType, Device, Module, Result, Tensor};
use candle_nn::{VarBuilder, VarMap};
use hush_net::{UNet, UNetConfig, UNetKind, init_weights};

use crate::{det_tensor, max_abs_diff};

fn build(in_channels: usize, width: f64) -> Result<(VarMap, UNet)> {
    let varmap = VarMap::new();
    let cfg = UNetConfig { kind: UNetKind::Unet, in_channels, out_channels: 3, width };
    let net = UNet::new(VarBuilder::from_varmap(&varmap, DType::F32, &Device::Cpu), &cfg)?;
    Ok((varmap, net))
}

fn param_count(varmap: &VarMap) -> usize {
    varmap.all_vars().iter().map(|v| v.elem_count()).sum()
}

/// anchors.md: OIDN's `unet` with 9 input channels has 919,811 parameters.
#[test]
fn parameter_count_matches_oidn() -> Result<()> {
    let (varmap, _) = build(9, 1.0)?;
    assert_eq!(param_count(&varmap), 919_811);
    let data = varmap.data().lock().unwrap();
    assert_eq!(data.len(), 32, "16 convolutions, each a weight and a bias");
    assert_eq!(data["enc_conv0.weight"].dims(), &[32, 9, 3, 3]);
    assert_eq!(data["dec_conv4a.weight"].dims(), &[112, 96 + 64, 3, 3]);
    assert_eq!(data["dec_conv1a.weight"].dims(), &[64, 64 + 9, 3, 3]);
    assert_eq!(data["dec_conv0.bias"].dims(), &[3]);
    Ok(())
}

#[test]
fn width_multiplier_rounds_and_keeps_one_channel() {
    let cfg = |width| UNetConfig { kind: UNetKind::Unet, in_channels: 9, out_channels: 3, width };
    assert_eq!(cfg(0.25).widths(), [8, 12, 16, 20, 24, 28, 24, 16, 16, 16, 8]);
    // 0.66 × 48 = 31.68 → 32, 0.66 × 80 = 52.8 → 53.
    assert_eq!(cfg(0.66).widths()[1], 32);
    assert_eq!(cfg(0.66).widths()[3], 53);
    assert_eq!(cfg(0.001).widths(), [1; 11]);
    assert!(cfg(0.0).validate().is_err());
    assert!(cfg(f64::NAN).validate().is_err());
}

#[test]
fn output_shape_and_size_errors() -> Result<()> {
    let (_, net) = build(6, 0.25)?;
    let x = det_tensor(&[2, 6, 32, 48], 0.0, 1.0, 1)?;
    assert_eq!(net.forward(&x)?.dims(), &[2, 3, 32, 48]);

    let err = net.forward(&det_tensor(&[1, 6, 20, 32], 0.0, 1.0, 2)?).unwrap_err().to_string();
    assert!(err.contains("20x32") && err.contains("multiples of 16"), "{err}");
    let err = net.forward(&det_tensor(&[1, 9, 16, 16], 0.0, 1.0, 3)?).unwrap_err().to_string();
    assert!(err.contains("9 channels") && err.contains("built for 6"), "{err}");

    // forward_padded: any size; the result is the top-left crop of the padded run.
    let x = det_tensor(&[1, 6, 20, 37], 0.0, 1.0, 4)?;
    let y = net.forward_padded(&x)?;
    assert_eq!(y.dims(), &[1, 3, 20, 37]);
    let padded = hush_net::pad_to_multiple(&x, 16)?;
    assert_eq!(padded.dims(), &[1, 6, 32, 48]);
    let full = net.forward(&padded)?;
    assert_eq!(max_abs_diff(&y, &hush_net::crop(&full, 20, 37)?)?, 0.0);
    Ok(())
}

/// Every one of the 32 tensors gets a finite, non-zero gradient: skips, pooling and upsampling all pass
/// gradients.
#[test]
fn gradients_reach_every_layer() -> Result<()> {
    let (varmap, net) = build(9, 0.25)?;
    init_weights(&varmap, 7)?;
    let x = det_tensor(&[1, 9, 32, 32], 0.0, 1.0, 5)?;
    let loss = net.forward(&x)?.sqr()?.mean_all()?;
    let grads = loss.backward()?;
    for (name, var) in varmap.data().lock().unwrap().iter() {
        let g = grads.get(var).unwrap_or_else(|| panic!("no gradient for {name}"));
        let v = g.flatten_all()?.to_vec1::<f32>()?;
        assert!(v.iter().all(|x| x.is_finite()), "{name}: non-finite gradient");
        assert!(v.iter().any(|x| *x != 0.0), "{name}: zero gradient");
    }
    Ok(())
}

/// Interleaved HWC buffers (hush-dataset's `Image`) to and from NCHW tensors.
#[test]
fn hwc_nchw_round_trip() -> Result<()> {
    let hwc: Vec<f32> = (0..2 * 3 * 4).map(|i| i as f32).collect(); // 3 wide, 2 high, 4 channels
    let t = hush_net::hwc_to_nchw(&hwc, 3, 2, 4, &Device::Cpu)?;
    assert_eq!(t.dims(), &[1, 4, 2, 3]);
    // Sample (x=2, y=1, c=3) is at (1 * 3 + 2) * 4 + 3 = 23.
    assert_eq!(t.get(0)?.get(3)?.get(1)?.get(2)?.to_scalar::<f32>()?, 23.0);
    assert_eq!(hush_net::nchw_to_hwc(&t)?, hwc);
    assert!(hush_net::hwc_to_nchw(&hwc, 3, 3, 4, &Device::Cpu).is_err());
    Ok(())
}

#[test]
fn seeded_init_is_reproducible_and_bounded() -> Result<()> {
    let (a, _) = build(9, 0.25)?;
    let (b, _) = build(9, 0.25)?;
    init_weights(&a, 42)?;
    init_weights(&b, 42)?;
    let (da, db) = (a.data().lock().unwrap(), b.data().lock().unwrap());
    for (name, va) in da.iter() {
        assert_eq!(max_abs_diff(va, &db[name])?, 0.0, "{name}");
    }
    // enc_conv0: fan-in 9 × 3 × 3 = 81, bound 1/9.
    let w = da["enc_conv0.weight"].flatten_all()?.to_vec1::<f32>()?;
    let max = w.iter().fold(0f32, |m, v| m.max(v.abs()));
    assert!(max <= 1.0 / 9.0 && max > 0.9 / 9.0, "max |w| = {max}");
    drop((da, db));
    init_weights(&b, 43)?;
    let w43 = b.data().lock().unwrap()["enc_conv0.weight"].clone();
    assert!(max_abs_diff(&a.data().lock().unwrap()["enc_conv0.weight"], &w43)? > 0.0);
    Ok(())
}

#[test]
fn config_serializes_with_oidn_kind_name() {
    let cfg = UNetConfig::oidn(12);
    let json = serde_json::to_string(&cfg).unwrap();
    assert_eq!(json, r#"{"kind":"unet","in_channels":12,"out_channels":3,"width":1.0}"#);
    assert_eq!(serde_json::from_str::<UNetConfig>(&json).unwrap(), cfg);
}

#[test]
fn forward_is_deterministic() -> Result<()> {
    let (varmap, net) = build(3, 0.25)?;
    init_weights(&varmap, 1)?;
    let x: Tensor = det_tensor(&[1, 3, 16, 16], 0.0, 1.0, 9)?;
    assert_eq!(max_abs_diff(&net.forward(&x)?, &net.forward(&x)?)?, 0.0);
    Ok(())
}
