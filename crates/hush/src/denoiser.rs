//! A trained model loaded from its file, applied to images.

use std::path::Path;

use anyhow::{Context, Result, bail};
use candle_core::Device;
use hush_dataset::Image;
use hush_net::{
    Feature, ModelInfo, UNet, build_input, finish_color, hwc_to_nchw, load_model, nchw_to_hwc, transfer::autoexposure,
};

/// The auxiliary image of a dataset view for one feature.
pub fn aux_of(view: &hush_dataset::ViewImages, f: Feature) -> &Image {
    match f {
        Feature::Albedo => &view.albedo,
        Feature::Normal => &view.normal,
        Feature::Diffuse => &view.diffuse,
        Feature::Specular => &view.specular,
    }
}

/// The device Candle runs on: the first CUDA device when built with `cuda`, else the CPU.
pub fn device() -> Result<Device> {
    #[cfg(feature = "cuda")]
    {
        return Ok(Device::new_cuda(0)?);
    }
    #[cfg(not(feature = "cuda"))]
    Ok(Device::Cpu)
}

pub struct Denoiser {
    net: UNet,
    pub info: ModelInfo,
    device: Device,
}

impl Denoiser {
    pub fn load(path: &Path) -> Result<Denoiser> {
        let bytes = std::fs::read(path).with_context(|| format!("reading model {}", path.display()))?;
        let device = device()?;
        let (net, info) = load_model(&bytes, &device).with_context(|| format!("loading model {}", path.display()))?;
        Ok(Denoiser { net, info, device })
    }

    /// The auxiliary features the model needs, in input order.
    pub fn features(&self) -> &[Feature] {
        &self.info.features.aux
    }

    /// Denoises linear HDR `color` with the auxiliary images in the order of [`Self::features`]:
    /// OIDN's pipeline (autoexposure of the input, transfer, U-Net, inverse transfer).
    pub fn denoise(&self, color: &Image, aux: &[&Image]) -> Result<Image> {
        if color.channels != 3 {
            bail!("the color image has {} channels; 3 (RGB) are needed", color.channels);
        }
        if aux.len() != self.features().len() {
            bail!(
                "the model needs {} auxiliary images ({}), {} were given",
                self.features().len(),
                self.info.features,
                aux.len()
            );
        }
        for (f, a) in self.features().iter().zip(aux) {
            if (a.width, a.height, a.channels) != (color.width, color.height, 3) {
                bail!(
                    "the {} image is {}×{}×{} but the color image is {}×{}×3",
                    f.long_name(),
                    a.width,
                    a.height,
                    a.channels,
                    color.width,
                    color.height
                );
            }
        }
        let (w, h) = (color.width, color.height);
        let exposure = autoexposure(&color.data, w, h);
        let aux_data: Vec<&[f32]> = aux.iter().map(|a| a.data.as_slice()).collect();
        let input = build_input(&self.info.features, w, h, &color.data, &aux_data, exposure, self.info.transfer)?;
        let x = hwc_to_nchw(&input, w, h, self.info.features.in_channels(), &self.device)?;
        let y = self.net.forward_padded(&x)?;
        let out = nchw_to_hwc(&y)?;
        Ok(Image::new(w, h, 3, finish_color(&out, exposure, self.info.transfer))?)
    }
}
