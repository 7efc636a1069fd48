//! hush's own shipped models (`data/models/`, retrained by `cargo xtask train-default`; each with its model
//! card beside it), built into the library, and the model `hush denoise` runs when it is given none.

use hush_net::{Feature, InputFeatures};

use crate::official::{OfficialWeights, official_for};

/// One of hush's shipped models.
#[derive(Clone, Copy, Debug)]
pub struct ShippedModel {
    /// Its file stem in `data/models/`, e.g. `hush_alb_nrm`.
    pub name: &'static str,
    /// Its auxiliary features after the color.
    pub aux: &'static [Feature],
    /// The safetensors file (`hush train`'s format).
    pub bytes: &'static [u8],
    /// How it runs by default: the setting under which its card's guards hold on the held-out scenes.
    pub inference: Inference,
}

/// How a denoiser runs a network on one image: in how many poses of the square
/// ([`crate::Denoiser::denoise_poses`]), and whether the input's low band is put back where they disagree
/// ([`crate::combine`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Inference {
    pub poses: usize,
    /// The Gaussian's std in pixels; `None`: the poses' mean as it is.
    pub restore_low_band: Option<f32>,
}

impl Inference {
    /// The network once, as OIDN's runtime runs it.
    pub const PLAIN: Inference = Inference { poses: 1, restore_low_band: None };
}

impl ShippedModel {
    /// The features the model takes.
    pub fn features(&self) -> InputFeatures {
        InputFeatures { aux: self.aux.to_vec() }
    }
}

/// The shipped models, each the default for inputs of exactly its features. `hush_alb_nrm` beats official
/// OIDN's `rt_hdr_alb_nrm` on the held-out scenes by the bar (+0.5 dB on average at 4–64 spp, no case
/// there below −0.3 dB); `hush_color` beats `rt_hdr` on average at every spp (+0.17 dB at 4–64 spp in one
/// pass, +0.21 as it runs here) and holds every guard as it runs here, but not the bar's worst case: on
/// veach-mis's own camera it loses up to 1.3 dB at 64 and 256 spp, in the few pixels beside a light smaller
/// than a pixel on a tent-filtered film, which OIDN fills in better (`data/models/hush_color.md`).
pub const DEFAULTS: [ShippedModel; 2] = [
    ShippedModel {
        name: "hush_alb_nrm",
        aux: &[Feature::Albedo, Feature::Normal],
        bytes: include_bytes!("../../../data/models/hush_alb_nrm.safetensors"),
        // Every guard on the test scenes holds in 8 poses with the low band at 2 px; with one pose three FLIP
        // guards at 256 spp fail (data/models/hush_alb_nrm.md).
        inference: Inference { poses: 8, restore_low_band: Some(2.0) },
    },
    ShippedModel {
        name: "hush_color",
        aux: &[],
        bytes: include_bytes!("../../../data/models/hush_color.safetensors"),
        // The same setting: every guard on the test scenes holds; with one pose veach-mis's FLIP at 256 spp
        // fails (as official OIDN's does there in one pass).
        inference: Inference { poses: 8, restore_low_band: Some(2.0) },
    },
];

/// What a denoiser without a chosen model runs.
#[derive(Clone, Copy, Debug)]
pub enum DefaultModel {
    /// A shipped hush model.
    Shipped(ShippedModel),
    /// OIDN's official weights (for inputs no shipped model is the default for).
    Official(OfficialWeights),
}

impl DefaultModel {
    /// How reports and messages name it: `hush_alb_nrm (shipped)` or `oidn-2.5.1 rt_hdr`.
    pub fn name(&self) -> String {
        match self {
            DefaultModel::Shipped(m) => format!("{} (shipped)", m.name),
            DefaultModel::Official(w) => w.method_name(),
        }
    }

    /// How it runs by default: the shipped model's [`ShippedModel::inference`], OIDN's weights plain.
    pub fn inference(&self) -> Inference {
        match self {
            DefaultModel::Shipped(m) => m.inference,
            DefaultModel::Official(_) => Inference::PLAIN,
        }
    }

    /// The denoiser on `device`.
    pub fn denoiser_on(&self, device: &candle_core::Device) -> anyhow::Result<crate::Denoiser> {
        match self {
            DefaultModel::Shipped(m) => crate::Denoiser::from_bytes_on(m.bytes, false, device),
            DefaultModel::Official(w) => crate::Denoiser::official_on(w, device),
        }
    }
}

/// The model for inputs of `features` when none is chosen: the shipped model that takes exactly them, else
/// OIDN's official weights for them ([`official_for`]).
pub fn default_for(features: &InputFeatures) -> DefaultModel {
    DEFAULTS
        .iter()
        .find(|m| m.aux == features.aux.as_slice())
        .map(|m| DefaultModel::Shipped(*m))
        .unwrap_or_else(|| DefaultModel::Official(official_for(features)))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The built-in bytes are the files in `data/models/`, and each is a model taking the features it is
    /// listed with.
    #[test]
    fn shipped_models_are_the_files_and_take_their_features() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data/models");
        for m in DEFAULTS {
            let file = std::fs::read(dir.join(format!("{}.safetensors", m.name))).unwrap();
            assert!(m.bytes == file.as_slice(), "{}", m.name);
            let d = crate::Denoiser::from_bytes_on(m.bytes, false, &candle_core::Device::Cpu).unwrap();
            assert_eq!(d.info.features, m.features(), "{}", m.name);
        }
        let with = |aux: &[Feature]| default_for(&InputFeatures { aux: aux.to_vec() }).name();
        assert_eq!(with(&[Feature::Albedo, Feature::Normal]), "hush_alb_nrm (shipped)");
        assert_eq!(with(&[]), "hush_color (shipped)");
        assert_eq!(with(&[Feature::Albedo]), "oidn-2.5.1 rt_hdr_alb");
    }
}
