//! Candle U-Nets, losses and HDR transfer functions for Monte-Carlo denoising. No file I/O.
//!
//! * [`UNet`] / [`UNetConfig`]: Open Image Denoise's `unet`, `unet_small` and `unet_large`, and the thesis'
//!   autoencoder without skips ([`UNetKind`]), with OIDN's layer names as weight keys (`enc_conv0.weight`,
//!   ..., `dec_conv0.bias`) and a width multiplier (the thesis' M1/M2 capacities). NCHW f32.
//!   [`init_weights`] gives a reproducible initialization (candle's CPU generator cannot be seeded).
//! * [`PatchMlp`] / [`PatchMlpConfig`]: Burger et al.'s plain MLP on overlapping 17×17 patches (stride 3),
//!   merged with a Gaussian window (thesis §7.5.1), a baseline on NCHW images of any size.
//! * [`Net`] / [`NetConfig`]: either network, as weight files record it and as training and inference build it.
//! * [`loss`]: L1, MSE, SSIM, MS-SSIM and the thesis' mix 0.16·L1 + 0.84·(1 − MS-SSIM); `ssim` doubles as
//!   the evaluation metric.
//! * [`transfer`]: autoexposure and the PU / log / sRGB transfer functions, on values and tensors.
//! * [`direct_conv_available`]: whether inference on this CPU takes the AVX-512 direct convolutions in
//!   a blocked layout (`direct.rs`) instead of Candle's path; training always takes Candle's.
//! * [`denoise`]: one image through OIDN's whole inference path (autoexposure, input, network, output).
//! * [`build_input`] (training) / [`build_inference_input`] (denoising) / [`prepare_color`] /
//!   [`finish_color`]: the network's input and output, as OIDN prepares them ([`InputFeatures`] says which auxiliary images go in, in which order).
//! * [`save_weights`] / [`load_weights`] / [`load_model`] / [`read_metadata`]: safetensors bytes carrying a
//!   [`ModelInfo`] (network, features, transfer) as metadata. Reading and writing files is the caller's job.
//! * [`Pretrained`]: trained weights (TZA or hush) to fine-tune from, matched by name and shape, their first
//!   convolution adapted to a larger feature set.
//! * [`load_tza`] / [`export_tza`] / [`parse_tza`] / [`write_tza`]: OIDN's Tensor Archive format, so hush runs
//!   OIDN's official weights and OIDN runs hush's.
//!
//! Device-agnostic: everything takes the device from its inputs or a `&Device`.
//!
//! ```
//! # fn main() -> candle_core::Result<()> {
//! use candle_core::{DType, Device, Module, Tensor};
//! use candle_nn::{VarBuilder, VarMap};
//! use hush_net::{UNet, UNetConfig, UNetKind};
//!
//! let device = Device::Cpu;
//! let cfg = UNetConfig::new(UNetKind::Unet, 9, 0.25);
//! let varmap = VarMap::new();
//! let net = UNet::new(VarBuilder::from_varmap(&varmap, DType::F32, &device), &cfg)?;
//!
//! // A 1×9×20×24 input (color, albedo, normal): padded to 32×32 inside, cropped back.
//! let noisy = Tensor::rand(0f32, 1f32, (1, 9, 20, 24), &device)?;
//! let denoised = net.forward_padded(&noisy)?;
//! assert_eq!(denoised.dims(), &[1, 3, 20, 24]);
//!
//! // Sizes that are multiples of 16 go straight through `Module::forward`.
//! let out = net.forward(&Tensor::zeros((2, 9, 32, 16), DType::F32, &device)?)?;
//! assert_eq!(out.dims(), &[2, 3, 32, 16]);
//! # Ok(())
//! # }
//! ```

mod conv;
mod denoise;
mod direct;
pub mod ensemble;
mod input;
pub mod loss;
mod net;
mod patch_mlp;
mod pretrained;
mod resample;
pub mod transfer;
mod tza;
mod unet;
mod weights;

pub use denoise::{blend_input, denoise, keep_exact_pixels};
pub use direct::available as direct_conv_available;
pub use input::{Feature, InputFeatures, build_inference_input, build_input, finish_color, prepare_color};
pub use loss::{Loss, LossSpace};
pub use net::{DenoiseNet, Net, NetConfig, PATCH_MLP_KIND};
pub use patch_mlp::{Activation, BURGER_HIDDEN, BURGER_PATCH, BURGER_STRIDE, PatchMlp, PatchMlpConfig};
pub use pretrained::Pretrained;
pub use tza::{TzaTensor, export_tza, infer_config, load_tza, oidn_features, parse_tza, write_tza};
pub use unet::{
    ALIGNMENT, ConvShape, Head, KERNEL_LAYER, MAX_KERNEL, THESIS_M1_WIDTH, THESIS_M2_WIDTH, UNet, UNetConfig, UNetKind,
    apply_kernels, crop, hwc_to_nchw, init_weights, nchw_to_hwc, pad_to_multiple,
};
pub use weights::{F32View, METADATA_KEY, ModelInfo, load_model, load_weights, read_metadata, save_weights};
