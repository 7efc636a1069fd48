//! Kernel prediction (`Head::Kernel`): the filtering, the network around it, starting it from a direct
//! network's weights, and what OIDN's format refuses.

use candle_core::{DType, Device, Module, Result, Tensor};
use candle_nn::{VarBuilder, VarMap};
use hush_net::{
    Head, InputFeatures, KERNEL_LAYER, ModelInfo, Net, NetConfig, Pretrained, UNetConfig, UNetKind, apply_kernels,
    init_weights, load_model, save_weights, transfer::Transfer,
};

use crate::{det_tensor, max_abs_diff};

/// The `size × size` mean of `color` at every pixel, the nearest edge pixel standing in beyond the
/// image: what zero logits (uniform weights) must give. Computed pixel by pixel, independently of
/// `apply_kernels`'s shifted slices.
fn box_filter(color: &Tensor, size: usize) -> Result<Tensor> {
    let (n, c, h, w) = color.dims4()?;
    let v = color.flatten_all()?.to_vec1::<f32>()?;
    let r = size as isize / 2;
    let at = |b: usize, ch: usize, y: isize, x: isize| {
        let (y, x) = (y.clamp(0, h as isize - 1) as usize, x.clamp(0, w as isize - 1) as usize);
        v[((b * c + ch) * h + y) * w + x]
    };
    let mut out = Vec::with_capacity(v.len());
    for b in 0..n {
        for ch in 0..c {
            for y in 0..h as isize {
                for x in 0..w as isize {
                    let mut sum = 0.0f64;
                    for dy in -r..=r {
                        for dx in -r..=r {
                            sum += at(b, ch, y + dy, x + dx) as f64;
                        }
                    }
                    out.push((sum / (size * size) as f64) as f32);
                }
            }
        }
    }
    Tensor::from_vec(out, (n, c, h, w), &Device::Cpu)
}

/// Uniform logits give the box filter (edges replicated, not zero); a logit far above the others at one
/// tap gives the color shifted by that tap's offset; any logits keep a constant image constant (the
/// weights sum to 1); and the gradient reaches the logits.
#[test]
fn predicted_kernels_filter_the_color() -> Result<()> {
    let (h, w, size) = (7, 9, 5);
    let color = det_tensor(&[2, 3, h, w], 0.0, 1.0, 11)?;
    let zeros = Tensor::zeros((2, size * size, h, w), DType::F32, &Device::Cpu)?;
    let got = apply_kernels(&zeros, &color, size)?;
    assert!(max_abs_diff(&got, &box_filter(&color, size)?)? < 1e-6, "uniform weights are a box filter");

    // Tap (dy, dx) = (+1, −2) from the centre: row-major index (2 + 1) · 5 + (2 − 2).
    let tap = 3 * size;
    let mut one_hot = vec![0f32; 2 * size * size * h * w];
    for b in 0..2 {
        for p in 0..h * w {
            one_hot[(b * size * size + tap) * h * w + p] = 60.0;
        }
    }
    let one_hot = Tensor::from_vec(one_hot, (2, size * size, h, w), &Device::Cpu)?;
    let shifted = apply_kernels(&one_hot, &color, size)?;
    let all = color.flatten_all()?.to_vec1::<f32>()?;
    let got = shifted.flatten_all()?.to_vec1::<f32>()?;
    for b in 0..2 {
        for ch in 0..3 {
            for y in 0..h {
                for x in 0..w {
                    let (sy, sx) = ((y + 1).min(h - 1), x.saturating_sub(2));
                    let want = all[((b * 3 + ch) * h + sy) * w + sx];
                    let i = ((b * 3 + ch) * h + y) * w + x;
                    assert!((got[i] - want).abs() < 1e-6, "pixel ({x}, {y}): {} against {want}", got[i]);
                }
            }
        }
    }

    let constant = Tensor::full(0.37f32, (2, 3, h, w), &Device::Cpu)?;
    let logits = det_tensor(&[2, size * size, h, w], -8.0, 8.0, 5)?;
    let out = apply_kernels(&logits, &constant, size)?;
    assert!(max_abs_diff(&out, &constant)? < 1e-6, "the weights sum to one");

    // Logits that record a gradient take the training path (whole channels of taps at once); it computes
    // what the inference path (tap by tap) does.
    let var = candle_core::Var::from_tensor(&logits)?;
    let trained = apply_kernels(var.as_tensor(), &color, size)?;
    assert!(trained.track_op());
    assert!(max_abs_diff(&trained, &apply_kernels(&logits, &color, size)?)? < 1e-6);
    let grads = trained.sqr()?.sum_all()?.backward()?;
    let g = grads.get(var.as_tensor()).expect("a gradient for the logits");
    assert!(g.abs()?.sum_all()?.to_scalar::<f32>()? > 0.0);

    assert!(apply_kernels(&zeros, &color, 3).is_err(), "25 logits are not a 3×3 kernel");
    Ok(())
}

fn direct_model(features: &str, seed: u64) -> Result<(VarMap, ModelInfo)> {
    let features = InputFeatures::parse(features)?;
    let net: NetConfig = UNetConfig::new(UNetKind::UnetSmall, features.in_channels(), 0.25).into();
    let varmap = VarMap::new();
    Net::new(VarBuilder::from_varmap(&varmap, DType::F32, &Device::Cpu), &net)?;
    init_weights(&varmap, seed)?;
    Ok((varmap, ModelInfo { net, features, transfer: Transfer::Pu }))
}

/// A direct network's weights start a kernel-predicting one: every encoder and decoder tensor is kept, the
/// kernel layer starts at zero, so the network first computes the box filter of its input's color, at any
/// image size (its kernels are cropped before they filter, so no pixel draws on the alignment padding). Its
/// description, its configuration file and its weight file say what it predicts, and OIDN's format
/// refuses it.
#[test]
fn a_direct_network_starts_a_kernel_predicting_one() -> Result<()> {
    let (source, info) = direct_model("alb,nrm", 3)?;
    let direct = Pretrained::read(&save_weights(&source, &info)?, &Device::Cpu)?;
    let size = 5;
    let kpn = direct.with_head(Head::Kernel { size })?;
    let NetConfig::UNet(cfg) = &kpn.info.net else { panic!("a U-Net") };
    assert_eq!(cfg.head, Head::Kernel { size });
    assert_eq!(kpn.info.net.describe(), "unet_small (width 0.25, 9 input channels, predicting 5×5 kernels)");
    let tensor = |p: &Pretrained, name: &str| p.tensors.iter().find(|(n, _)| n == name).map(|(_, t)| t.clone());
    assert!(tensor(&kpn, "dec_conv0.weight").is_none(), "the direct output layer is dropped");
    let head = tensor(&kpn, &format!("{KERNEL_LAYER}.weight")).expect("the kernel layer");
    assert_eq!(head.dims(), &[25, 8, 3, 3]);
    assert_eq!(head.abs()?.sum_all()?.to_scalar::<f32>()?, 0.0);
    for name in ["enc_conv0.weight", "dec_conv1b.bias"] {
        assert_eq!(
            tensor(&kpn, name).unwrap().flatten_all()?.to_vec1::<f32>()?,
            tensor(&direct, name).unwrap().flatten_all()?.to_vec1::<f32>()?,
            "{name} is kept"
        );
    }

    let varmap = VarMap::new();
    let net = Net::new(VarBuilder::from_varmap(&varmap, DType::F32, &Device::Cpu), &kpn.info.net)?;
    kpn.load_into(&varmap)?;
    let x = det_tensor(&[1, 9, 21, 13], 0.0, 1.0, 7)?;
    let y = net.forward_padded(&x)?;
    assert_eq!(y.dims(), &[1, 3, 21, 13]);
    assert!(max_abs_diff(&y, &box_filter(&x.narrow(1, 0, 3)?, size)?)? < 1e-5, "zero kernels are box filters");

    // The file says what the network is, and reads back as the same network.
    let bytes = save_weights(&varmap, &kpn.info)?;
    let (back, back_info) = load_model(&bytes, &Device::Cpu)?;
    assert_eq!(back_info, kpn.info);
    assert!(max_abs_diff(&back.forward_padded(&x)?, &y)? < 1e-6);
    let json = serde_json::to_string(&kpn.info.net).unwrap();
    assert!(json.contains(r#""head":{"kernel":{"size":5}}"#), "{json}");
    assert!(!serde_json::to_string(&info.net).unwrap().contains("head"), "a direct network writes no head");

    let err = net.export_tza().unwrap_err().to_string();
    assert!(err.contains("OIDN") && err.contains("kernel") && err.contains(".safetensors"), "{err}");
    let err = kpn.with_head(Head::Direct).unwrap_err().to_string();
    assert!(err.contains("cannot start"), "{err}");
    let err = kpn.with_head(Head::Kernel { size: 7 }).unwrap_err().to_string();
    assert!(err.contains("5×5 kernels, not 7×7"), "{err}");
    Ok(())
}

/// The frozen network (which on a CPU with AVX-512 runs the inference convolutions) computes what the
/// trained one does, to f32 rounding; a kernel-predicting network has the kernel layer in place of the
/// output layer and counts its filtering among its multiply-adds.
#[test]
fn kernel_networks_run_frozen_and_count_their_work() -> Result<()> {
    let cfg = UNetConfig::new(UNetKind::UnetSmall, 3, 0.25).with_head(Head::Kernel { size: 7 });
    let varmap = VarMap::new();
    let net = Net::new(VarBuilder::from_varmap(&varmap, DType::F32, &Device::Cpu), &cfg.clone().into())?;
    init_weights(&varmap, 9)?;
    let x = det_tensor(&[1, 3, 32, 16], 0.0, 1.0, 2)?;
    let (trained, frozen) = (net.forward(&x)?, net.frozen()?.forward(&x)?);
    assert!(trained.track_op() && !frozen.track_op());
    assert!(max_abs_diff(&trained, &frozen)? <= 1e-5);
    let direct = UNetConfig::new(UNetKind::UnetSmall, 3, 0.25);
    let shapes = cfg.conv_shapes();
    assert_eq!(shapes.last().map(|s| (s.name, s.out_channels)), Some((KERNEL_LAYER, 49)));
    let (h, w) = (32, 16);
    let head = |c: &UNetConfig| {
        let s = c.conv_shapes().pop().unwrap();
        (s.in_channels * s.out_channels * 9 * h * w) as u64
    };
    assert_eq!(
        cfg.multiply_adds(h, w) - head(&cfg),
        direct.multiply_adds(h, w) - head(&direct) + (49 * 3 * h * w) as u64
    );
    for bad in [4, 1, 23] {
        assert!(UNetConfig::new(UNetKind::Unet, 3, 1.0).with_head(Head::Kernel { size: bad }).validate().is_err());
    }
    assert_eq!(Head::parse("kernel:9"), Some(Head::Kernel { size: 9 }));
    assert_eq!(Head::parse("kernel"), Some(Head::Kernel { size: 5 }));
    assert_eq!(Head::parse("kernel:8"), None);
    assert_eq!(Head::parse(&Head::Kernel { size: 21 }.name()), Some(Head::Kernel { size: 21 }));
    Ok(())
}

/// Kernels averaging in linear light (`kernel_linear`): with zero logits the network's output is the transfer
/// of the box filter of the linear color, which is brighter than the transfer space's box filter wherever
/// the neighbourhood's values differ (Jensen's inequality for the concave PU curve), and equal to it on a
/// constant image. The setting is written to the model file and read back; a transfer other than the
/// model's, or a direct network with a kernel space, is refused.
#[test]
fn kernels_average_in_linear_light_when_asked() -> Result<()> {
    let (source, info) = direct_model("alb,nrm", 5)?;
    let kpn = Pretrained::read(&save_weights(&source, &info)?, &Device::Cpu)?.with_head(Head::Kernel { size: 3 })?;
    let linear_net = kpn.info.net.with_kernel_linear(Some(Transfer::Pu));
    let varmap = VarMap::new();
    let net = Net::new(VarBuilder::from_varmap(&varmap, DType::F32, &Device::Cpu), &linear_net)?;
    kpn.load_into(&varmap)?;
    let x = det_tensor(&[1, 9, 16, 16], 0.0, 1.0, 3)?;
    let color = x.narrow(1, 0, 3)?;
    let want = Transfer::Pu.forward_tensor(&box_filter(&Transfer::Pu.inverse_tensor(&color)?, 3)?)?;
    let got = net.forward_padded(&x)?;
    assert!(max_abs_diff(&got, &want)? < 1e-5, "the transfer of the linear box filter");
    let in_transfer_space = box_filter(&color, 3)?;
    let brighter = (&got - &in_transfer_space)?.flatten_all()?.min(0)?.to_scalar::<f32>()?;
    assert!(brighter > -1e-6, "never darker than the transfer-space average, by Jensen: {brighter}");
    assert!((&got - &in_transfer_space)?.mean_all()?.to_scalar::<f32>()? > 1e-3, "and brighter where values differ");
    let constant = Tensor::ones((1, 9, 16, 16), DType::F32, &Device::Cpu)?.affine(0.4, 0.0)?;
    assert!(max_abs_diff(&net.forward_padded(&constant)?.narrow(1, 0, 3)?, &constant.narrow(1, 0, 3)?)? < 1e-5);

    let linear_info = ModelInfo { net: linear_net.clone(), ..kpn.info.clone() };
    assert!(linear_info.net.describe().ends_with("predicting 3×3 kernels averaging in linear light)"));
    let (back, back_info) = load_model(&save_weights(&varmap, &linear_info)?, &Device::Cpu)?;
    assert_eq!(back_info, linear_info);
    assert!(max_abs_diff(&back.forward_padded(&x)?, &got)? < 1e-6);
    let json = serde_json::to_string(&linear_info.net).unwrap();
    assert!(json.contains(r#""kernel_linear":"pu""#), "{json}");
    assert!(!serde_json::to_string(&kpn.info.net).unwrap().contains("kernel_linear"), "unset: not written");

    let err = ModelInfo { transfer: Transfer::Log, ..linear_info }.validate().unwrap_err().to_string();
    assert!(err.contains("Pu") && err.contains("Log"), "{err}");
    let direct = UNetConfig::new(UNetKind::Unet, 3, 1.0).with_kernel_linear(Some(Transfer::Pu));
    assert!(direct.validate().is_err(), "a direct network averages nothing");
    let cfg = linear_net.as_unet().unwrap();
    assert_eq!(cfg.with_head(Head::Direct).kernel_linear, None, "a direct head drops the kernel space");
    Ok(())
}
