//! What the network sees: noisy HDR color plus auxiliary features, prepared as Open Image Denoise does.
//!
//! Per pixel, as OIDN's `core/input_process_kernel.h` (runtime) and `training/dataset.py` (training):
//! * color: sanitized (below), × exposure, then the transfer function. For **training** ([`build_input`],
//!   [`prepare_color`], also the target) the result is clamped to ≤ 1, as OIDN's `preprocess.py` clamps the
//!   transferred color and target. For **inference** ([`build_inference_input`]) it is not: OIDN's runtime
//!   clamps only to [0, FLT_MAX] before the transfer, so radiance above 65504 / exposure reaches the
//!   network as values > 1, and hush must do the same to reproduce OIDN's output with OIDN's weights;
//! * albedo-like features (albedo, diffuse, specular reflectance): sanitized, clamped to [0, 1];
//! * normals: sanitized, clamped to [-1, 1], then mapped to [0, 1] by `n · 0.5 + 0.5`;
//! * the color's variance (per pixel and channel, the variance of the pixel's value: its samples'
//!   variance over their count, as `hush render` writes it): sanitized, its square root (the standard
//!   error, in radiance) × exposure through the color's transfer function, clamped to [0, 1], so the
//!   network sees the noise's size in the units it sees the color in. Not an OIDN input.
//!
//! **Non-finite input** (the sanitization policy): NaN, +Inf and −Inf samples become 0, as do negative
//! color samples, in every feature, before anything else; [`crate::transfer::autoexposure`] ignores them
//! the same way. A broken sample thus costs one dark sample, never the image: OIDN 2.5.1 treats NaN, −Inf
//! and negatives so too, but lets +Inf through its autoexposure, which then returns 0 and the whole output
//! turns black. hush deliberately departs from OIDN there; finite input is processed exactly like OIDN.
//!
//! Channel order: color first, then the auxiliary features in the order of [`InputFeatures::aux`], 3 each.

use candle_core::{Result, bail};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::transfer::Transfer;

/// An auxiliary feature image (3 channels each).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Feature {
    /// Reflectance at the first non-specular hit.
    Albedo,
    /// Shading normal at the first hit, components in [-1, 1].
    Normal,
    /// Diffuse reflectance k_d at the first non-specular hit (thesis §6.2).
    Diffuse,
    /// Specular reflectance k_s at the first non-specular hit (thesis §6.2).
    Specular,
    /// The variance of the noisy color's pixel values (of its samples, over their count): where the noise
    /// is, which one noisy image cannot tell a network (Bako et al. 2017; thesis §9).
    Variance,
}

impl Feature {
    pub const ALL: [Feature; 5] =
        [Feature::Albedo, Feature::Normal, Feature::Diffuse, Feature::Specular, Feature::Variance];

    /// The short name used in file names and feature lists: `alb`, `nrm`, `diff`, `spec`, `var`.
    pub fn short_name(self) -> &'static str {
        match self {
            Feature::Albedo => "alb",
            Feature::Normal => "nrm",
            Feature::Diffuse => "diff",
            Feature::Specular => "spec",
            Feature::Variance => "var",
        }
    }

    /// The long name, as serialized: `albedo`, `normal`, `diffuse`, `specular`, `variance`.
    pub fn long_name(self) -> &'static str {
        match self {
            Feature::Albedo => "albedo",
            Feature::Normal => "normal",
            Feature::Diffuse => "diffuse",
            Feature::Specular => "specular",
            Feature::Variance => "variance",
        }
    }

    /// Parses a short name (`alb`) or a long one (`albedo`).
    pub fn parse(name: &str) -> Option<Feature> {
        Feature::ALL.into_iter().find(|f| name == f.short_name() || name == f.long_name())
    }

    /// The network's view of one feature sample (the module docs), with the color's `exposure` and
    /// `transfer`.
    fn prepare(self, v: f32, exposure: f32, transfer: Transfer) -> f32 {
        let v = sanitize(v);
        match self {
            Feature::Normal => v.clamp(-1.0, 1.0) * 0.5 + 0.5,
            Feature::Albedo | Feature::Diffuse | Feature::Specular => v.clamp(0.0, 1.0),
            Feature::Variance => prepare_color_unclamped(v.max(0.0).sqrt(), exposure, transfer).min(1.0),
        }
    }
}

/// The network's input features: the noisy color (always, first) and the auxiliary features in order.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct InputFeatures {
    pub aux: Vec<Feature>,
}

impl InputFeatures {
    /// Fails on a repeated feature.
    pub fn new(aux: Vec<Feature>) -> Result<Self> {
        for (i, f) in aux.iter().enumerate() {
            if aux[..i].contains(f) {
                bail!("feature {} is listed twice", f.short_name())
            }
        }
        Ok(InputFeatures { aux })
    }

    /// Parses a comma-separated list of auxiliary features, e.g. `"diff,spec,nrm"` (the thesis' best) or
    /// `"alb,nrm"` (OIDN's); `""` or `"none"` means color only. `hdr` or `color` (the always-present noisy color) is accepted and ignored.
    pub fn parse(list: &str) -> Result<Self> {
        let mut aux = Vec::new();
        for name in list.split(',').map(str::trim).filter(|s| !s.is_empty() && !matches!(*s, "none" | "hdr" | "color"))
        {
            match Feature::parse(name) {
                Some(f) => aux.push(f),
                None => bail!("unknown feature {name:?}; known: alb, nrm, diff, spec, var"),
            }
        }
        InputFeatures::new(aux)
    }

    /// 3 for the color plus 3 per auxiliary feature.
    pub fn in_channels(&self) -> usize {
        3 + 3 * self.aux.len()
    }
}

impl std::fmt::Display for InputFeatures {
    /// `hdr,diff,spec,nrm`: the form [`InputFeatures::parse`] reads back.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("hdr")?;
        for a in &self.aux {
            write!(f, ",{}", a.short_name())?;
        }
        Ok(())
    }
}

/// The sanitization policy of the module docs: non-finite samples become 0.
fn sanitize(v: f32) -> f32 {
    if v.is_finite() { v } else { 0.0 }
}

/// Color radiance for the network without the ≤ 1 clamp: `transfer(min(FLT_MAX, exposure · max(0, v)))`,
/// OIDN's runtime (whose clamp after the scaling keeps huge finite values finite).
fn prepare_color_unclamped(v: f32, exposure: f32, transfer: Transfer) -> f32 {
    transfer.forward((sanitize(v).max(0.0) * exposure).min(f32::MAX))
}

/// Color (or target) radiance as the network sees it in training: `min(1, transfer(exposure · max(0, v)))`,
/// non-finite → 0.
pub fn prepare_color(rgb: &[f32], exposure: f32, transfer: Transfer) -> Vec<f32> {
    rgb.iter().map(|&v| prepare_color_unclamped(v, exposure, transfer).min(1.0)).collect()
}

/// The inverse of [`prepare_color`] for network output, as OIDN's `core/output_process_kernel.h`: NaN → 0,
/// clamp ≥ 0, inverse transfer, ÷ exposure.
pub fn finish_color(out: &[f32], exposure: f32, transfer: Transfer) -> Vec<f32> {
    let mut v = out.to_vec();
    finish_color_in_place(&mut v, exposure, transfer);
    v
}

/// [`finish_color`] in place. Element by element (so the thread count cannot change the result), in
/// parallel: the inverse transfer's powers are a tenth of a 512² inference on one thread.
pub(crate) fn finish_color_in_place(out: &mut [f32], exposure: f32, transfer: Transfer) {
    out.par_iter_mut().for_each(|v| {
        let x = if v.is_nan() { 0.0 } else { v.max(0.0) };
        *v = transfer.inverse(x).max(0.0) / exposure;
    });
}

/// Which color clamp an input is built with (see the module docs).
#[derive(Clone, Copy)]
enum Stage {
    Training,
    Inference,
}

/// Builds the interleaved (HWC) network input **for training** from linear color and the auxiliary images
/// listed in `features` (same order), each interleaved RGB/XYZ of `width × height × 3` values. `exposure` is
/// that of the reference (as OIDN's `preprocess.py` does, so input and target share it). The transferred
/// color is clamped to ≤ 1; use [`build_inference_input`] to denoise.
pub fn build_input(
    features: &InputFeatures,
    width: usize,
    height: usize,
    color: &[f32],
    aux: &[&[f32]],
    exposure: f32,
    transfer: Transfer,
) -> Result<Vec<f32>> {
    build(Stage::Training, features, width, height, color, aux, exposure, transfer)
}

/// Builds the interleaved (HWC) network input **for denoising**, exactly as OIDN's runtime does
/// (`core/input_process_kernel.h`): like [`build_input`] but the transferred color is not clamped to ≤ 1.
/// `exposure` is usually [`crate::transfer::autoexposure`] of the color (OIDN's `inputScale`).
pub fn build_inference_input(
    features: &InputFeatures,
    width: usize,
    height: usize,
    color: &[f32],
    aux: &[&[f32]],
    exposure: f32,
    transfer: Transfer,
) -> Result<Vec<f32>> {
    build(Stage::Inference, features, width, height, color, aux, exposure, transfer)
}

#[allow(clippy::too_many_arguments)]
fn build(
    stage: Stage,
    features: &InputFeatures,
    width: usize,
    height: usize,
    color: &[f32],
    aux: &[&[f32]],
    exposure: f32,
    transfer: Transfer,
) -> Result<Vec<f32>> {
    let n = width * height * 3;
    if color.len() != n {
        bail!("build_input: color has {} values, a {width}x{height} RGB image needs {n}", color.len())
    }
    if aux.len() != features.aux.len() {
        bail!("build_input: {} auxiliary images given for features {features}", aux.len())
    }
    for (f, a) in features.aux.iter().zip(aux) {
        if a.len() != n {
            bail!("build_input: {} has {} values, a {width}x{height}x3 image needs {n}", f.short_name(), a.len())
        }
    }
    if !(exposure.is_finite() && exposure > 0.0) {
        bail!("build_input: exposure must be finite and > 0, got {exposure}")
    }
    let channels = features.in_channels();
    let color: Vec<f32> = match stage {
        Stage::Training => prepare_color(color, exposure, transfer),
        Stage::Inference => color.par_iter().map(|&v| prepare_color_unclamped(v, exposure, transfer)).collect(),
    };
    let mut out = Vec::with_capacity(width * height * channels);
    for p in 0..width * height {
        out.extend_from_slice(&color[3 * p..3 * p + 3]);
        for (f, a) in features.aux.iter().zip(aux) {
            out.extend(a[3 * p..3 * p + 3].iter().map(|&v| f.prepare(v, exposure, transfer)));
        }
    }
    Ok(out)
}
