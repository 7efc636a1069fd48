use candle_core::{DType, Device, Module, Result};
use candle_nn::{VarBuilder, VarMap};
use hush_net::transfer::Transfer;
use hush_net::{
    Activation, InputFeatures, ModelInfo, Net, PatchMlpConfig, UNet, UNetConfig, UNetKind, init_weights, load_model,
    load_weights, read_metadata, save_weights,
};

use crate::{det_tensor, max_abs_diff};

fn info(width: f64) -> ModelInfo {
    let features = InputFeatures::parse("alb,nrm").unwrap();
    let net = UNetConfig::new(UNetKind::Unet, features.in_channels(), width);
    ModelInfo { net: net.into(), features, transfer: Transfer::Pu }
}

fn build(info: &ModelInfo, seed: u64) -> Result<(VarMap, UNet)> {
    let varmap = VarMap::new();
    let net = UNet::new(VarBuilder::from_varmap(&varmap, DType::F32, &Device::Cpu), info.net.as_unet().unwrap())?;
    init_weights(&varmap, seed)?;
    Ok((varmap, net))
}

/// save → load into a differently initialized network → bit-identical outputs; the metadata comes back;
/// a network loaded from the bytes holds the same tensors bit for bit.
#[test]
fn safetensors_round_trip() -> Result<()> {
    let info = info(0.25);
    let (varmap, net) = build(&info, 1)?;
    let x = det_tensor(&[1, 9, 16, 32], 0.0, 1.0, 20)?;
    let y = net.forward(&x)?;
    let bytes = save_weights(&varmap, &info)?;
    assert_eq!(read_metadata(&bytes)?, Some(info.clone()));

    let (other_map, other) = build(&info, 2)?;
    assert!(max_abs_diff(&other.forward(&x)?, &y)? > 1e-4, "different seeds should give different outputs");
    load_weights(&other_map, &bytes)?;
    assert_eq!(max_abs_diff(&other.forward(&x)?, &y)?, 0.0);

    let (loaded, loaded_info) = load_model(&bytes, &Device::Cpu)?;
    assert_eq!(loaded_info, info);
    {
        let saved = varmap.data().lock().unwrap();
        for (name, t) in loaded.named_tensors() {
            assert_eq!(max_abs_diff(&t, saved[&name].as_tensor())?, 0.0, "{name} changed in the round trip");
        }
    }
    // Plain tensors take the inference path (on AVX-512 CPUs `direct.rs`, whose sums run in another
    // order): equal up to f32 rounding, 1e-5 of the largest output as `inference_path_matches_training_path`
    // bounds it.
    let scale = y.abs()?.max_all()?.to_scalar::<f32>()?;
    assert!(max_abs_diff(&loaded.forward(&x)?, &y)? <= 1e-5 * scale);

    // The tolerance above can fail: nudging one bias by 1e-3 changes the output.
    let data = other_map.data().lock().unwrap();
    let b = &data["dec_conv0.bias"];
    b.set(&(b.as_tensor() + 1e-3)?)?;
    drop(data);
    assert!(max_abs_diff(&other.forward(&x)?, &y)? > 5e-4);
    Ok(())
}

#[test]
fn oidn_tensor_names_are_the_keys() -> Result<()> {
    let info = info(0.25);
    let (varmap, _) = build(&info, 3)?;
    let bytes = save_weights(&varmap, &info)?;
    let tensors = candle_core::safetensors::load_buffer(&bytes, &Device::Cpu)?;
    assert_eq!(tensors.len(), 32);
    for name in ["enc_conv0", "enc_conv5b", "dec_conv4a", "dec_conv1b", "dec_conv0"] {
        assert!(tensors.contains_key(&format!("{name}.weight")) && tensors.contains_key(&format!("{name}.bias")));
    }
    Ok(())
}

#[test]
fn mismatches_are_clear_errors() -> Result<()> {
    let small = info(0.25);
    let (small_map, _) = build(&small, 4)?;
    let bytes = save_weights(&small_map, &small)?;
    let (wide_map, _) = build(&info(0.5), 5)?;
    let err = load_weights(&wide_map, &bytes).unwrap_err().to_string();
    assert!(err.contains("shape") && err.contains("in the file"), "{err}");

    // A file without hush metadata: no ModelInfo, and load_model says why.
    let plain = safetensors::tensor::serialize(
        [("x", safetensors::tensor::TensorView::new(safetensors::Dtype::F32, vec![1], &[0u8; 4]).unwrap())],
        None,
    )
    .unwrap();
    assert_eq!(read_metadata(&plain)?, None);
    assert!(load_model(&plain, &Device::Cpu).unwrap_err().to_string().contains("hush.config"));
    let err = load_weights(&small_map, &plain).unwrap_err().to_string();
    assert!(err.contains("\"x\""), "{err}");
    assert!(read_metadata(b"not a safetensors file").is_err());

    // Metadata whose channel count disagrees with its features is refused when saving.
    let mut bad = small.clone();
    bad.net = bad.net.with_in_channels(12);
    assert!(save_weights(&small_map, &bad).unwrap_err().to_string().contains("12 input channels"));
    Ok(())
}

/// The patch MLP is a model like the U-Nets: its weights file records it, `load_model` rebuilds it, and the
/// rebuilt network gives bit-identical outputs on an image whose size is not a multiple of the stride.
#[test]
fn patch_mlp_round_trip() -> Result<()> {
    let features = InputFeatures::parse("alb,nrm").unwrap();
    let cfg = PatchMlpConfig::burger(features.in_channels(), 0.01, Activation::Tanh);
    let info = ModelInfo { net: cfg.clone().into(), features, transfer: Transfer::Pu };
    let varmap = VarMap::new();
    let net = Net::new(VarBuilder::from_varmap(&varmap, DType::F32, &Device::Cpu), &info.net)?;
    init_weights(&varmap, 6)?;
    let x = det_tensor(&[1, 9, 22, 19], 0.0, 1.0, 21)?;
    let y = net.forward(&x)?;
    assert_eq!(y.dims(), &[1, 3, 22, 19]);
    let bytes = save_weights(&varmap, &info)?;
    let (loaded, loaded_info) = load_model(&bytes, &Device::Cpu)?;
    assert_eq!(loaded_info, info);
    assert!(matches!(loaded, Net::PatchMlp(_)));
    assert_eq!(max_abs_diff(&loaded.forward_padded(&x)?, &y)?, 0.0);
    // A U-Net's weights are not a patch MLP's: the error names the tensors.
    let (unet_map, _) = build(&self::info(0.25), 7)?;
    let err = load_weights(&varmap, &save_weights(&unet_map, &self::info(0.25))?).unwrap_err().to_string();
    assert!(err.contains("enc_conv0"), "{err}");
    Ok(())
}
