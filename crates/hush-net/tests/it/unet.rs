use candle_core::{DType, Device, Module, Result, Tensor};
use candle_nn::{VarBuilder, VarMap};
use hush_net::{THESIS_M1_WIDTH, THESIS_M2_WIDTH, UNet, UNetConfig, UNetKind, init_weights};

use crate::{det_tensor, max_abs_diff};

fn build(in_channels: usize, width: f64) -> Result<(VarMap, UNet)> {
    let varmap = VarMap::new();
    let cfg = UNetConfig::new(UNetKind::Unet, in_channels, width);
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

/// Hidden widths are ⌊base × width⌋ (at least 1), the thesis' rule.
#[test]
fn width_multiplier_floors_and_keeps_one_channel() {
    let widths = |width: f64| -> Vec<usize> {
        let cfg = UNetConfig::new(UNetKind::Unet, 9, width);
        cfg.conv_shapes().iter().map(|s| s.out_channels).collect()
    };
    // enc_conv0, enc_conv1, enc_conv2, ..., dec_conv1b, then dec_conv0 (always 3).
    assert_eq!(widths(1.0), [32, 32, 48, 64, 80, 96, 96, 112, 112, 96, 96, 64, 64, 64, 32, 3]);
    assert_eq!(widths(0.25), [8, 8, 12, 16, 20, 24, 24, 28, 28, 24, 24, 16, 16, 16, 8, 3]);
    // 0.66 × 48 = 31.68 → 31, 0.66 × 80 = 52.8 → 52, 0.1 × 80 = 8 exactly (not 7.999…).
    assert_eq!(widths(0.66)[2], 31);
    assert_eq!(widths(0.66)[4], 52);
    assert_eq!(widths(0.1)[4], 8);
    assert_eq!(widths(0.001), [1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 3]);
    let cfg = |width| UNetConfig::new(UNetKind::Unet, 9, width);
    assert!(cfg(0.0).validate().is_err());
    assert!(cfg(f64::NAN).validate().is_err());
}

/// The thesis' capacities (§7.5.2): M1 has c1 = ⌊c·0.66⌋ and M2 c2 = ⌊c1·0.5⌋ for every hidden width c;
/// the M2 width multiplier 0.33 gives exactly that for every layer of every kind.
#[test]
fn thesis_capacities_m1_and_m2() {
    for kind in UNetKind::ALL {
        let at = |width| UNetConfig::new(kind, 12, width).conv_shapes();
        let (full, m1, m2) = (at(1.0), at(THESIS_M1_WIDTH), at(THESIS_M2_WIDTH));
        for ((c, c1), c2) in full.iter().zip(&m1).zip(&m2).take(full.len() - 1) {
            let expect1 = (c.out_channels as f64 * 0.66).floor() as usize;
            assert_eq!(c1.out_channels, expect1, "{kind:?} {}", c.name);
            assert_eq!(c2.out_channels, expect1 / 2, "{kind:?} {}", c.name);
        }
    }
    assert_eq!(UNetConfig::thesis_m1(12).width, THESIS_M1_WIDTH);
    assert_eq!(UNetConfig::thesis_m2(12).width, THESIS_M2_WIDTH);
    // M_OIDN > M1 > M2 in parameters (12 inputs, as the thesis trained them).
    let p = |cfg: UNetConfig| cfg.parameter_count();
    let (full, m1, m2) = (p(UNetConfig::oidn(12)), p(UNetConfig::thesis_m1(12)), p(UNetConfig::thesis_m2(12)));
    assert!(full > m1 && m1 > m2, "{full} {m1} {m2}");
}

/// Multiply-adds per forward pass: OIDN's `unet` on 9 channels at 512² is 65.75 GFLOP (2 FLOP per
/// multiply-add) in `../shared/docs/anchors.md`, i.e. 125,406 multiply-adds per pixel; halving each side
/// quarters the count, and the autoencoder (no concatenated skips) does fewer.
#[test]
fn multiply_adds_match_oidn_count() {
    let unet = UNetConfig::oidn(9);
    assert_eq!(unet.multiply_adds(512, 512), 125_406 * 512 * 512);
    assert_eq!(unet.multiply_adds(256, 256) * 4, unet.multiply_adds(512, 512));
    assert!(UNetConfig::thesis_dae(9).multiply_adds(64, 64) < unet.multiply_adds(64, 64));
    assert!(UNetConfig::thesis_m2(9).multiply_adds(64, 64) < UNetConfig::thesis_m1(9).multiply_adds(64, 64));
}

/// Layer names, shapes and parameter counts of every kind, checked against OIDN's own weight files
/// (`rt_hdr*.tza`: 914,627 / 917,219 / 919,811 for `unet` with 3 / 6 / 9 inputs, 320,035 for
/// `unet_small`, 3,848,387 for `unet_large`).
#[test]
fn kinds_have_oidn_layers_and_parameter_counts() -> Result<()> {
    let count = |kind, in_channels| UNetConfig::new(kind, in_channels, 1.0).parameter_count();
    assert_eq!(count(UNetKind::Unet, 3), 914_627);
    assert_eq!(count(UNetKind::Unet, 6), 917_219);
    assert_eq!(count(UNetKind::Unet, 9), 919_811);
    assert_eq!(count(UNetKind::UnetSmall, 9), 320_035);
    assert_eq!(count(UNetKind::UnetLarge, 9), 3_848_387);

    let shapes = |kind| UNetConfig::new(kind, 9, 1.0).conv_shapes();
    let large = shapes(UNetKind::UnetLarge);
    assert_eq!(large.len(), 19);
    assert_eq!((large[0].name, large[0].in_channels, large[0].out_channels), ("enc_conv1a", 9, 64));
    assert_eq!((large[1].name, large[1].in_channels, large[1].out_channels), ("enc_conv1b", 64, 64));
    let by_name = |v: &[hush_net::ConvShape], n: &str| v.iter().find(|s| s.name == n).cloned().unwrap();
    assert_eq!(by_name(&large, "dec_conv4a").in_channels, 256 + 128);
    assert_eq!(by_name(&large, "dec_conv1a").in_channels, 96 + 9);
    assert_eq!((large[18].name, large[18].in_channels, large[18].out_channels), ("dec_conv1c", 64, 3));
    let small = shapes(UNetKind::UnetSmall);
    assert_eq!(by_name(&small, "dec_conv3a").in_channels, 64 + 32);
    assert_eq!(by_name(&small, "dec_conv1a").in_channels, 32 + 9);

    // The autoencoder is `unet` without the concatenations.
    let dae = shapes(UNetKind::Autoencoder);
    let unet = shapes(UNetKind::Unet);
    assert_eq!(dae.iter().map(|s| s.name).collect::<Vec<_>>(), unet.iter().map(|s| s.name).collect::<Vec<_>>());
    for (name, without, with) in
        [("dec_conv4a", 96, 96 + 64), ("dec_conv3a", 112, 112 + 48), ("dec_conv1a", 64, 64 + 9)]
    {
        assert_eq!(by_name(&dae, name).in_channels, without, "{name}");
        assert_eq!(by_name(&unet, name).in_channels, with, "{name}");
    }
    Ok(())
}

/// Every kind runs, keeps the spatial size, and names its tensors after its layers.
#[test]
fn every_kind_runs_and_names_its_tensors() -> Result<()> {
    for kind in UNetKind::ALL {
        let varmap = VarMap::new();
        let cfg = UNetConfig::new(kind, 6, 0.125);
        let net = UNet::new(VarBuilder::from_varmap(&varmap, DType::F32, &Device::Cpu), &cfg)?;
        init_weights(&varmap, 3)?;
        let y = net.forward_padded(&det_tensor(&[1, 6, 20, 24], 0.0, 1.0, 6)?)?;
        assert_eq!(y.dims(), &[1, 3, 20, 24], "{kind:?}");
        let names: Vec<String> = net.named_tensors().into_iter().map(|(n, _)| n).collect();
        let mut keys: Vec<String> = varmap.data().lock().unwrap().keys().cloned().collect();
        keys.sort();
        let mut sorted = names.clone();
        sorted.sort();
        assert_eq!(sorted, keys, "{kind:?}");
        assert_eq!(names.len(), 2 * cfg.conv_shapes().len());
        assert_eq!(serde_json::to_string(&kind).unwrap(), format!("\"{}\"", kind.name()));
        assert_eq!(UNetKind::parse(kind.name()), Some(kind));
    }
    Ok(())
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
    for kind in UNetKind::ALL {
        let varmap = VarMap::new();
        let cfg = UNetConfig::new(kind, 9, 0.25);
        let net = UNet::new(VarBuilder::from_varmap(&varmap, DType::F32, &Device::Cpu), &cfg)?;
        init_weights(&varmap, 7)?;
        let x = det_tensor(&[1, 9, 32, 32], 0.0, 1.0, 5)?;
        let loss = net.forward(&x)?.sqr()?.mean_all()?;
        let grads = loss.backward()?;
        for (name, var) in varmap.data().lock().unwrap().iter() {
            let g = grads.get(var).unwrap_or_else(|| panic!("{kind:?}: no gradient for {name}"));
            let v = g.flatten_all()?.to_vec1::<f32>()?;
            assert!(v.iter().all(|x| x.is_finite()), "{kind:?} {name}: non-finite gradient");
            assert!(v.iter().any(|x| *x != 0.0), "{kind:?} {name}: zero gradient");
        }
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

/// The inference path (plain weight tensors: on an AVX-512 CPU, the direct convolutions in blocked
/// layout) computes what the training path (variables: Candle's Winograd and im2col convolutions) does,
/// for every kind, at widths whose channel counts are not multiples of 16, on a non-square input whose
/// bottleneck has an odd side (so that the direct kernels run beside Winograd's). The tolerance, 1e-5 of
/// the output's largest magnitude, is f32 rounding through 16–22 layers of sums of up to 2,300 products
/// in different orders (measured: at most 1.2e-6); a wrong tap, lane, transform coefficient or skip
/// channel is off by far more (a sign flipped in the output transform: 0.8).
#[test]
fn inference_path_matches_training_path() -> Result<()> {
    if !hush_net::direct_conv_available() {
        eprintln!("no AVX-512 here: inference takes the training path, nothing to compare");
        return Ok(());
    }
    for (kind, width, features) in [
        (UNetKind::Unet, 1.0, "alb,nrm"),
        (UNetKind::Unet, 0.66, "diff,spec,nrm"),
        (UNetKind::UnetSmall, 1.0, ""),
        (UNetKind::UnetLarge, 0.25, "alb,nrm"),
        (UNetKind::Autoencoder, 0.5, "alb"),
    ] {
        let features = hush_net::InputFeatures::parse(features)?;
        let in_channels = features.in_channels();
        let cfg = UNetConfig::new(kind, in_channels, width);
        let varmap = VarMap::new();
        let trained = UNet::new(VarBuilder::from_varmap(&varmap, DType::F32, &Device::Cpu), &cfg)?;
        init_weights(&varmap, 7)?;
        let info =
            hush_net::ModelInfo { net: cfg.clone().into(), features, transfer: hush_net::transfer::Transfer::Pu };
        let (loaded, _) = hush_net::load_model(&hush_net::save_weights(&varmap, &info)?, &Device::Cpu)?;
        let x = det_tensor(&[2, in_channels, 48, 32], 0.0, 1.0, 11)?;
        let want = trained.forward(&x)?;
        let got = loaded.forward_padded(&x)?;
        assert_eq!(got.dims(), want.dims());
        // The second call runs in the memory planned from the first; the result is the same, bit for bit.
        assert_eq!(max_abs_diff(&loaded.forward_padded(&x)?, &got)?, 0.0, "{kind:?}: a planned call differs");
        let scale = want.abs()?.max_all()?.to_scalar::<f32>()?;
        let diff = max_abs_diff(&got, &want)?;
        assert!(diff <= 1e-5 * scale, "{kind:?} width {width}: max |diff| {diff} against max |y| {scale}");
    }
    Ok(())
}
