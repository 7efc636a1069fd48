//! Training samples and the random crops, flips and batches drawn from them.

use hush_dataset::Image;
use hush_hash::SplitMix64;
use hush_net::transfer::{Transfer, autoexposure};
use hush_net::{Feature, InputFeatures, build_input, prepare_color};
use serde::{Deserialize, Serialize};

use crate::{Result, TrainError};

/// The version of what [`TrainSample::from_linear`] makes of a dataset's images (exposure, transfer
/// function, the features' preparation): part of every sample cache's key, so a change here must bump it
/// and caches prepared the old way are rebuilt rather than trusted.
pub const PREPARATION_VERSION: u32 = 1;

/// One training pair, already in the network's space: `input` has the network's input channels
/// (color, then the auxiliary features) and `target` 3 channels, both interleaved (HWC) and the same size.
#[derive(Clone, Debug, PartialEq)]
pub struct TrainSample {
    pub input: Image,
    pub target: Image,
}

impl TrainSample {
    /// Prepares a sample from linear images as OIDN's training toolkit does (`preprocess.py`): the
    /// exposure is the autoexposure of the *reference*, applied to both the noisy color and the target
    /// before the transfer function; auxiliary features are prepared by [`hush_net::build_input`]. `aux`
    /// must follow `features.aux` in order; every image has 3 channels and the reference's size.
    pub fn from_linear(
        features: &InputFeatures,
        transfer: Transfer,
        color: &Image,
        aux: &[&Image],
        reference: &Image,
    ) -> Result<Self> {
        let (w, h) = (reference.width, reference.height);
        let named = std::iter::once(("color", color))
            .chain(features.aux.iter().map(|f| f.short_name()).zip(aux.iter().copied()))
            .chain(std::iter::once(("reference", reference)));
        for (name, im) in named {
            if (im.width, im.height, im.channels) != (w, h, 3) {
                return Err(TrainError::Data(format!(
                    "{name} is {}x{}x{} but the reference is {w}x{h}x3",
                    im.width, im.height, im.channels
                )));
            }
        }
        if aux.len() != features.aux.len() {
            return Err(TrainError::Data(format!("{} auxiliary images given for features {features}", aux.len())));
        }
        let exposure = autoexposure(&reference.data, w, h);
        let aux_data: Vec<&[f32]> = aux.iter().map(|im| im.data.as_slice()).collect();
        let input = build_input(features, w, h, &color.data, &aux_data, exposure, transfer)?;
        let target = prepare_color(&reference.data, exposure, transfer);
        Ok(TrainSample {
            input: Image { width: w, height: h, channels: features.in_channels(), data: input },
            target: Image { width: w, height: h, channels: 3, data: target },
        })
    }
}

/// Data augmentation of the random crops.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Augment {
    /// Random crops only (the thesis).
    Crop,
    /// Random crops in one of 8 orientations (flips and transposition, as OIDN).
    #[default]
    Flips,
    /// As `Flips`, plus OIDN's channel permutations: one random RGB permutation shared by the color, the
    /// reflectance features and the target, another for the normal's xyz.
    FlipsPermute,
}

impl Augment {
    /// `crop`/`none`, `flips`, `full`/`oidn`/`flips_permute`.
    pub fn parse(name: &str) -> Option<Self> {
        Some(match name {
            "crop" | "none" => Augment::Crop,
            "flips" | "flip" => Augment::Flips,
            "full" | "oidn" | "flips_permute" => Augment::FlipsPermute,
            _ => return None,
        })
    }
}

/// Where one batch item comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Crop {
    /// Index into the training samples.
    pub sample: usize,
    pub x: usize,
    pub y: usize,
    /// Bit 0: mirror horizontally, bit 1: mirror vertically, bit 2: transpose (8 orientations).
    pub orientation: u8,
    /// Index into [`PERMUTATIONS`] of the color/reflectance/target channels.
    pub color_perm: u8,
    /// Index into [`PERMUTATIONS`] of the normal's channels.
    pub normal_perm: u8,
}

impl std::fmt::Display for Crop {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "sample {} at ({}, {}) orientation {}", self.sample, self.x, self.y, self.orientation)
    }
}

/// The 6 permutations of 3 channels; index 0 is the identity.
pub const PERMUTATIONS: [[usize; 3]; 6] = [[0, 1, 2], [0, 2, 1], [1, 0, 2], [1, 2, 0], [2, 0, 1], [2, 1, 0]];

/// Draws crops from a counter-based random stream: the `k`-th crop of the run is a pure function of
/// (seed, k), so the sampler's whole state is the number of crops drawn, a resumed run continues the same
/// sequence, and batches can be prepared ahead on another thread. Samples are visited in a freshly
/// shuffled order per pass; each crop has a uniform random window and, when augmenting, orientation and
/// channel permutations.
#[derive(Clone, Debug)]
pub(crate) struct Sampler {
    seed: u64,
    sizes: Vec<(usize, usize)>,
    crop: usize,
    augment: Augment,
    /// The shuffled order of one pass, cached.
    order: (u64, Vec<usize>),
}

impl Sampler {
    pub fn new(seed: u64, samples: &[TrainSample], crop: usize, augment: Augment) -> Self {
        let sizes = samples.iter().map(|s| (s.input.width, s.input.height)).collect();
        Sampler { seed, sizes, crop, augment, order: (u64::MAX, Vec::new()) }
    }

    /// The crop drawn `k`-th (0-based) in the run.
    pub fn crop(&mut self, k: u64) -> Crop {
        let n = self.sizes.len() as u64;
        let pass = k / n;
        if self.order.0 != pass {
            let mut rng = SplitMix64::keyed(self.seed, 0x6f_7264_6572 ^ pass.rotate_left(17));
            let mut order: Vec<usize> = (0..self.sizes.len()).collect();
            for i in (1..order.len()).rev() {
                order.swap(i, rng.below(i as u64 + 1) as usize);
            }
            self.order = (pass, order);
        }
        let sample = self.order.1[(k % n) as usize];
        let (w, h) = self.sizes[sample];
        let mut rng = SplitMix64::keyed(self.seed, k);
        let x = rng.below((w - self.crop + 1) as u64) as usize;
        let y = rng.below((h - self.crop + 1) as u64) as usize;
        let (orientation, color_perm, normal_perm) = match self.augment {
            Augment::Crop => (0, 0, 0),
            Augment::Flips => (rng.below(8) as u8, 0, 0),
            Augment::FlipsPermute => (rng.below(8) as u8, rng.below(6) as u8, rng.below(6) as u8),
        };
        Crop { sample, x, y, orientation, color_perm, normal_perm }
    }

    /// The crops of 1-based optimizer step `step` with `batch` crops per step.
    pub fn batch(&mut self, step: usize, batch: usize) -> Vec<Crop> {
        let first = (step as u64 - 1) * batch as u64;
        (first..first + batch as u64).map(|k| self.crop(k)).collect()
    }
}

/// For each input channel, the channel of the unpermuted image it is read from, given the crop's
/// permutations: color and reflectance features follow `color_perm`, normals `normal_perm`.
pub(crate) fn channel_sources(features: &InputFeatures, crop: &Crop, target: bool) -> Vec<usize> {
    let cp = PERMUTATIONS[crop.color_perm as usize];
    let np = PERMUTATIONS[crop.normal_perm as usize];
    if target {
        return cp.to_vec();
    }
    let mut out = cp.to_vec();
    for (g, f) in features.aux.iter().enumerate() {
        let p = if *f == Feature::Normal { np } else { cp };
        out.extend(p.iter().map(|&k| 3 * (g + 1) + k));
    }
    out
}

/// Copies the crops of the inputs (or targets) into an NCHW buffer of `crops.len() × channels × size²`.
pub(crate) fn gather(
    samples: &[TrainSample],
    features: &InputFeatures,
    crops: &[Crop],
    target: bool,
    size: usize,
) -> Vec<f32> {
    fn pick(s: &TrainSample, target: bool) -> &Image {
        if target { &s.target } else { &s.input }
    }
    let channels = pick(&samples[crops[0].sample], target).channels;
    let plane = size * size;
    let mut data = vec![0f32; crops.len() * channels * plane];
    for (b, crop) in crops.iter().enumerate() {
        let im = pick(&samples[crop.sample], target);
        let sources = channel_sources(features, crop, target);
        let item = &mut data[b * channels * plane..(b + 1) * channels * plane];
        for oy in 0..size {
            for ox in 0..size {
                let (mut sx, mut sy) = if crop.orientation & 4 != 0 { (oy, ox) } else { (ox, oy) };
                if crop.orientation & 1 != 0 {
                    sx = size - 1 - sx;
                }
                if crop.orientation & 2 != 0 {
                    sy = size - 1 - sy;
                }
                let src = ((crop.y + sy) * im.width + crop.x + sx) * channels;
                for (c, &from) in sources.iter().enumerate() {
                    item[c * plane + oy * size + ox] = im.data[src + from];
                }
            }
        }
    }
    data
}
