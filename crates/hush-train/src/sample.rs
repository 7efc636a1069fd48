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
    /// All of OIDN's training toolkit (`TrainingDataset` in its `dataset.py`): as `FlipsPermute`, plus one
    /// crop in ten shrunk by 0 to 15 pixels on each side and zero-padded at its bottom and right after the
    /// flips (so that the network sees the padding an image whose sides are not multiples of 16 gets), and,
    /// where there are auxiliary features, one crop in a hundred with its color and target zeroed (so that a
    /// black image stays black instead of ghosting its features).
    Oidn,
}

impl Augment {
    /// `crop`/`none`, `flips`, `full`/`flips_permute`, `oidn`.
    pub fn parse(name: &str) -> Option<Self> {
        Some(match name {
            "crop" | "none" => Augment::Crop,
            "flips" | "flip" => Augment::Flips,
            "full" | "flips_permute" => Augment::FlipsPermute,
            "oidn" => Augment::Oidn,
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
    /// Pixels the crop lacks of the crop size along x and y of the image (0 to 15: OIDN's shrunk crops);
    /// the tile is zero-padded at its bottom and right after the orientation is applied.
    pub shrink: [u8; 2],
    /// Whether the color input and the target are zeroed (OIDN's black samples).
    pub zeroed: bool,
}

/// The most pixels a shrunk crop lacks on a side, plus one (OIDN's `max_padding`).
const MAX_PADDING: u64 = 16;

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
    /// Whether the input has auxiliary features (OIDN zeroes samples only then).
    aux: bool,
    /// The shuffled order of one pass, cached.
    order: (u64, Vec<usize>),
}

impl Sampler {
    pub fn new(seed: u64, samples: &[TrainSample], crop: usize, augment: Augment) -> Self {
        let sizes = samples.iter().map(|s| (s.input.width, s.input.height)).collect();
        let aux = samples.first().is_some_and(|s| s.input.channels > 3);
        Sampler { seed, sizes, crop, augment, aux, order: (u64::MAX, Vec::new()) }
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
        // Drawn before the window (which depends on it) only in the mode that has it, so that every other
        // mode draws exactly the sequence it always did.
        let shrink = match self.augment {
            Augment::Oidn if rng.next_f64() < 0.1 => [rng.below(MAX_PADDING) as u8, rng.below(MAX_PADDING) as u8],
            _ => [0, 0],
        };
        let (cw, ch) = (self.crop - shrink[0] as usize, self.crop - shrink[1] as usize);
        let x = rng.below((w - cw + 1) as u64) as usize;
        let y = rng.below((h - ch + 1) as u64) as usize;
        let (orientation, color_perm, normal_perm) = match self.augment {
            Augment::Crop => (0, 0, 0),
            Augment::Flips => (rng.below(8) as u8, 0, 0),
            Augment::FlipsPermute | Augment::Oidn => (rng.below(8) as u8, rng.below(6) as u8, rng.below(6) as u8),
        };
        let zeroed = self.augment == Augment::Oidn && self.aux && rng.next_f64() < 0.01;
        Crop { sample, x, y, orientation, color_perm, normal_perm, shrink, zeroed }
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
        // The window in the image, and the tile it fills after the orientation; the rest stays zero.
        let (cw, ch) = (size - crop.shrink[0] as usize, size - crop.shrink[1] as usize);
        let transposed = crop.orientation & 4 != 0;
        let (tw, th) = if transposed { (ch, cw) } else { (cw, ch) };
        // A zeroed sample keeps only its auxiliary features, but not the color's variance: a black input
        // with the noise of the rendered one would contradict itself.
        let first = if crop.zeroed { if target { channels } else { 3 } } else { 0 };
        let zeroed_too =
            |c: usize| crop.zeroed && !target && c >= 3 && features.aux.get((c - 3) / 3) == Some(&Feature::Variance);
        for oy in 0..th {
            for ox in 0..tw {
                let (mut sx, mut sy) = if transposed { (oy, ox) } else { (ox, oy) };
                if crop.orientation & 1 != 0 {
                    sx = cw - 1 - sx;
                }
                if crop.orientation & 2 != 0 {
                    sy = ch - 1 - sy;
                }
                let src = ((crop.y + sy) * im.width + crop.x + sx) * channels;
                for (c, &from) in sources.iter().enumerate().skip(first) {
                    if !zeroed_too(c) {
                        item[c * plane + oy * size + ox] = im.data[src + from];
                    }
                }
            }
        }
    }
    data
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A sample whose input channel c of pixel (x, y) holds 1 + c + 10 x + 1000 y (never 0), and whose
    /// target holds the same for its 3 channels.
    fn sample(w: usize, h: usize, channels: usize) -> TrainSample {
        let image = |channels: usize| Image {
            width: w,
            height: h,
            channels,
            data: (0..w * h * channels)
                .map(|i| {
                    let (px, c) = (i / channels, i % channels);
                    (1 + c + 10 * (px % w) + 1000 * (px / w)) as f32
                })
                .collect(),
        };
        TrainSample { input: image(channels), target: image(3) }
    }

    #[test]
    fn other_modes_draw_the_crops_they_always_did() {
        // The first crops of seed 7 at 32² from a 64² image, as the sampler drew them before the `oidn` mode
        // existed (window x, y, orientation, colour and normal permutations; checked against an independent
        // SplitMix64): a change to the stream would change every run and break every resume.
        let samples = vec![sample(64, 64, 9)];
        let mut s = Sampler::new(7, &samples, 32, Augment::FlipsPermute);
        let drawn: Vec<(usize, usize, u8, u8, u8)> =
            (0..3).map(|k| s.crop(k)).map(|c| (c.x, c.y, c.orientation, c.color_perm, c.normal_perm)).collect();
        assert_eq!(drawn, [(20, 11, 1, 0, 3), (27, 16, 5, 3, 1), (6, 10, 7, 2, 2)]);
        assert!((0..100).map(|k| s.crop(k)).all(|c| c.shrink == [0, 0] && !c.zeroed));
    }

    #[test]
    fn oidn_mode_shrinks_one_crop_in_ten_and_zeroes_one_in_a_hundred() {
        let n = 4000;
        let with_aux = vec![sample(64, 64, 9)];
        let mut s = Sampler::new(3, &with_aux, 32, Augment::Oidn);
        let crops: Vec<Crop> = (0..n).map(|k| s.crop(k)).collect();
        let shrunk = crops.iter().filter(|c| c.shrink != [0, 0]).count();
        let zeroed = crops.iter().filter(|c| c.zeroed).count();
        // Binomial: 10 % of 4000 is 400 ± 19 (one sd; 1/16 of the shrunk draws are [0, 0]: 375 expected), 1 %
        // is 40 ± 6.3; the bounds are over 4 sd wide.
        assert!((295..=455).contains(&shrunk), "{shrunk} shrunk crops of {n}");
        assert!((15..=66).contains(&zeroed), "{zeroed} zeroed crops of {n}");
        assert!(crops.iter().all(|c| c.shrink.iter().all(|&p| u64::from(p) < MAX_PADDING)));
        let color_only = vec![sample(64, 64, 3)];
        let mut s = Sampler::new(3, &color_only, 32, Augment::Oidn);
        assert!((0..n).all(|k| !s.crop(k).zeroed), "a sample without auxiliary features is never zeroed");
    }

    #[test]
    fn a_shrunk_crop_is_zero_padded_at_the_bottom_and_right_after_its_orientation() {
        let samples = vec![sample(40, 40, 9)];
        let features = InputFeatures::parse("alb,nrm").unwrap();
        let size = 16;
        for orientation in 0..8u8 {
            let crop = Crop {
                sample: 0,
                x: 5,
                y: 7,
                orientation,
                color_perm: 0,
                normal_perm: 0,
                shrink: [3, 5],
                zeroed: false,
            };
            let data = gather(&samples, &features, &[crop], false, size);
            let (cw, ch) = (size - 3, size - 5);
            let (tw, th) = if orientation & 4 != 0 { (ch, cw) } else { (cw, ch) };
            let at = |c: usize, x: usize, y: usize| data[c * size * size + y * size + x];
            for y in 0..size {
                for x in 0..size {
                    let inside = x < tw && y < th;
                    assert_eq!(at(0, x, y) != 0.0, inside, "orientation {orientation}, pixel ({x}, {y})");
                }
            }
            // The tile's corner pixels are the window's corners, as the orientation moves them.
            let value = |sx: usize, sy: usize| (1 + 10 * (5 + sx) + 1000 * (7 + sy)) as f32;
            let (mut corners, mut expected) = (Vec::new(), Vec::new());
            for (x, y) in [(0, 0), (tw - 1, 0), (0, th - 1), (tw - 1, th - 1)] {
                corners.push(at(0, x, y));
            }
            for (x, y) in [(0, 0), (cw - 1, 0), (0, ch - 1), (cw - 1, ch - 1)] {
                expected.push(value(x, y));
            }
            corners.sort_by(f32::total_cmp);
            expected.sort_by(f32::total_cmp);
            assert_eq!(corners, expected, "orientation {orientation}");
        }
    }

    #[test]
    fn a_zeroed_crop_keeps_only_its_auxiliary_features() {
        let samples = vec![sample(32, 32, 9)];
        let features = InputFeatures::parse("alb,nrm").unwrap();
        let crop =
            Crop { sample: 0, x: 0, y: 0, orientation: 0, color_perm: 0, normal_perm: 0, shrink: [0, 0], zeroed: true };
        let input = gather(&samples, &features, &[crop], false, 16);
        let target = gather(&samples, &features, &[crop], true, 16);
        let plane = 16 * 16;
        assert!(input[..3 * plane].iter().all(|&v| v == 0.0), "color zeroed");
        assert!(input[3 * plane..].iter().all(|&v| v != 0.0), "features kept");
        assert!(target.iter().all(|&v| v == 0.0), "target zeroed");

        // The color's variance goes with the color: a black input has no noise.
        let samples = vec![sample(32, 32, 12)];
        let features = InputFeatures::parse("alb,var,nrm").unwrap();
        let input = gather(&samples, &features, &[crop], false, 16);
        let channel = |c: usize| &input[c * plane..(c + 1) * plane];
        for c in 0..12 {
            let zero = c < 3 || (6..9).contains(&c);
            assert!(channel(c).iter().all(|&v| (v == 0.0) == zero), "channel {c}: zeroed {zero}");
        }
    }
}
