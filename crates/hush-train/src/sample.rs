//! Training samples and the random crops, flips and batches drawn from them.

use candle_core::{Device, Tensor};
use hush_dataset::Image;
use hush_net::transfer::{Transfer, autoexposure};
use hush_net::{Features, build_input, prepare_color};
use rand::rngs::StdRng;
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};

use crate::{Result, TrainError};

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
        features: &Features,
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

/// Where one batch item comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Crop {
    pub sample: usize,
    pub x: usize,
    pub y: usize,
    /// Bit 0: mirror horizontally, bit 1: mirror vertically, bit 2: transpose (8 orientations).
    pub orientation: u8,
}

/// Draws crops: samples in a freshly shuffled order each epoch, a uniform random window in each, and a
/// random orientation when augmenting. Everything comes from one seeded generator.
pub(crate) struct Sampler {
    rng: StdRng,
    order: Vec<usize>,
    next: usize,
    pub epoch: usize,
    sizes: Vec<(usize, usize)>,
    crop: usize,
    augment: bool,
}

impl Sampler {
    pub fn new(seed: u64, samples: &[TrainSample], crop: usize, augment: bool) -> Self {
        let sizes = samples.iter().map(|s| (s.input.width, s.input.height)).collect();
        Sampler { rng: StdRng::seed_from_u64(seed), order: Vec::new(), next: 0, epoch: 0, sizes, crop, augment }
    }

    pub fn next_crop(&mut self) -> Crop {
        if self.next == self.order.len() {
            self.order = (0..self.sizes.len()).collect();
            self.order.shuffle(&mut self.rng);
            self.next = 0;
            self.epoch += 1;
        }
        let sample = self.order[self.next];
        self.next += 1;
        let (w, h) = self.sizes[sample];
        let x = self.rng.random_range(0..=w - self.crop);
        let y = self.rng.random_range(0..=h - self.crop);
        let orientation = if self.augment { self.rng.random_range(0..8u8) } else { 0 };
        Crop { sample, x, y, orientation }
    }
}

/// Copies the crops of one image of each sample into an NCHW tensor (`pick` chooses input or target).
pub(crate) fn gather(
    samples: &[TrainSample],
    crops: &[Crop],
    pick: fn(&TrainSample) -> &Image,
    size: usize,
    device: &Device,
) -> Result<Tensor> {
    let channels = pick(&samples[crops[0].sample]).channels;
    let plane = size * size;
    let mut data = vec![0f32; crops.len() * channels * plane];
    for (b, crop) in crops.iter().enumerate() {
        let im = pick(&samples[crop.sample]);
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
                for c in 0..channels {
                    item[c * plane + oy * size + ox] = im.data[src + c];
                }
            }
        }
    }
    Ok(Tensor::from_vec(data, (crops.len(), channels, size, size), device)?)
}
