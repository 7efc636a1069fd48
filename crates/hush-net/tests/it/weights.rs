use candle_core::{DType, Device, Module, Result};
use candle_nn::{VarBuilder, VarMap};
use hush_net::transfer::Transfer;
use hush_net::{
    Features, ModelInfo, UNet, UNetConfig, UNetKind, init_weights, load_model, load_weights, read_metadata,
    save_weights,
};

use crate::{det_tensor, max_abs_diff};

fn info(width: f64) -> ModelInfo {
    let features = Features::parse("alb,nrm").unwrap();
    let net = UNetConfig { kind: UNetKind::Unet, in_channels: features.in_channels(), out_channels: 3, width };
    ModelInfo { net, features, transfer: Transfer::Pu }
}

fn build(info: &ModelInfo, seed: u64) -> Result<(VarMap, UNet)> {
    let varmap = VarMap::new();
    let net = UNet::new(VarBuilder::from_varmap(&varmap, DType::F32, &Device::Cpu), &info.net)?;
    init_weights(&varmap, seed)?;
    Ok((varmap, net))
}

/// save → load into a differently initialized network → bit-identical outputs; the metadata comes back.
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
    assert_eq!(max_abs_diff(&loaded.forward(&x)?, &y)?, 0.0);

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
    bad.net.in_channels = 12;
    assert!(save_weights(&small_map, &bad).unwrap_err().to_string().contains("12 input channels"));
    Ok(())
}
