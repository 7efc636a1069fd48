//! Trained weights to start a training run from (fine-tuning): OIDN's official TZA weights or a hush model,
//! matched to the network being trained tensor by tensor, by name and shape.
//!
//! **Changing the input features.** A network trained on one feature set can start one that takes more: the
//! first convolution's weights are copied per input feature, 3 channels at a time, by feature
//! ([`Pretrained::adapt`]):
//! * the color and every feature the source also had keep their weights (in every convolution that reads the
//!   input: the first, and the last decoder level's, which the U-Net's skip feeds the input too);
//! * `diffuse` takes the source's `albedo` weights when the source had albedo but no diffuse and the new set
//!   has no albedo (on diffuse surfaces the albedo *is* the diffuse reflectance, so OIDN's `alb,nrm` weights
//!   start a `diff,spec,nrm` network close to where they were; beside the albedo itself it starts at zero);
//! * every other new feature starts at zero, so it changes nothing until training gives it weight.
//!
//! With only same-name copies and zeros, the adapted network computes exactly what the source did. A feature
//! the source had that the new set drops is refused: its weights cannot be removed without changing what the
//! network computes (start from weights trained without it, e.g. OIDN's `rt_hdr.tza` for color only).
//! The patch MLP's first layer mixes channels within patches; it keeps its features as they were.
//!
//! **Changing the output head.** A direct U-Net's weights start a kernel-predicting one of the same kind and
//! width ([`Pretrained::with_head`]): encoder and decoder keep their weights, the direct output layer is
//! dropped and the kernel layer starts at zero, so every predicted kernel starts as a box filter of its
//! size and training shapes it from the features OIDN's encoder and decoder already compute.

use std::collections::HashMap;

use candle_core::{DType, Device, Result, Tensor, bail};
use candle_nn::VarMap;

use crate::input::{Feature, InputFeatures};
use crate::net::NetConfig;
use crate::transfer::Transfer;
use crate::tza::{infer_config, oidn_features, parse_tza};
use crate::unet::{Head, KERNEL_LAYER, UNetConfig};
use crate::weights::{ModelInfo, read_metadata, serialize_weights};

/// A trained network's tensors by name and what it is ([`ModelInfo`]).
#[derive(Clone, Debug)]
pub struct Pretrained {
    pub info: ModelInfo,
    pub tensors: Vec<(String, Tensor)>,
}

impl Pretrained {
    /// Reads a TZA archive (OIDN's official weights: features from the channel count as
    /// [`oidn_features`], PU transfer) or a self-describing hush safetensors file, told apart by their
    /// first bytes.
    pub fn read(bytes: &[u8], device: &Device) -> Result<Pretrained> {
        if bytes.starts_with(&[0xD7, 0x41]) {
            Self::from_tza(bytes, device)
        } else {
            Self::from_safetensors(bytes, device)
        }
    }

    /// OIDN's TZA weights.
    pub fn from_tza(bytes: &[u8], device: &Device) -> Result<Pretrained> {
        let tensors = parse_tza(bytes)?;
        let net = infer_config(&tensors)?;
        let features = oidn_features(net.in_channels)?;
        let info = ModelInfo { net: net.into(), features, transfer: Transfer::Pu };
        let tensors = tensors
            .into_iter()
            .map(|t| Ok((t.name, Tensor::from_vec(t.values, t.dims, device)?)))
            .collect::<Result<Vec<_>>>()?;
        Ok(Pretrained { info, tensors })
    }

    /// A hush model (`model.safetensors` of `hush train`, whose metadata says what it is).
    pub fn from_safetensors(bytes: &[u8], device: &Device) -> Result<Pretrained> {
        let Some(info) = read_metadata(bytes)? else {
            bail!("the weight file is neither a TZA archive nor a hush model (its safetensors metadata has no network)")
        };
        info.validate()?;
        let mut tensors = candle_core::safetensors::load_buffer(bytes, device)?
            .into_iter()
            .map(|(k, v)| Ok((k, v.to_dtype(DType::F32)?)))
            .collect::<Result<Vec<_>>>()?;
        tensors.sort_by(|a, b| a.0.cmp(&b.0));
        Ok(Pretrained { info, tensors })
    }

    /// These weights for a network taking `features` (the module docs say how channels are matched). The
    /// same features return the weights unchanged.
    pub fn adapt(&self, features: &InputFeatures) -> Result<Pretrained> {
        let from = &self.info.features;
        if from == features {
            return Ok(self.clone());
        }
        let NetConfig::UNet(unet) = &self.info.net else {
            bail!("a patch MLP's input features cannot change: train it with {from}, its features")
        };
        let takes_albedo_as_diffuse = |f: &Feature| {
            *f == Feature::Albedo && features.aux.contains(&Feature::Diffuse) && !from.aux.contains(&Feature::Diffuse)
        };
        if let Some(dropped) = from.aux.iter().find(|f| !features.aux.contains(f) && !takes_albedo_as_diffuse(f)) {
            bail!(
                "the weights take {from}; {features} drops {}, whose weights cannot be removed without changing \
                 what the network computes; start from weights trained without it or keep the feature",
                dropped.long_name()
            )
        }
        // The source's input channel of each new feature's first channel: color at 0, then its features.
        let source_slot = |f: Feature| from.aux.iter().position(|&g| g == f).map(|i| 3 + 3 * i);
        let slots: Vec<Option<usize>> = std::iter::once(Some(0))
            .chain(features.aux.iter().map(|&f| {
                source_slot(f).or(match f {
                    // Only where the albedo itself is no input: else its weights would count twice.
                    Feature::Diffuse if !features.aux.contains(&Feature::Albedo) => source_slot(Feature::Albedo),
                    _ => None,
                })
            }))
            .collect();
        // Every convolution that reads the network's input (the first, and with skips the last decoder
        // level's first, which concatenates the input after the upsampled features) takes more channels.
        let target = UNetConfig { in_channels: features.in_channels(), ..unet.clone() };
        let source_input = unet.in_channels;
        let mut tensors = self.tensors.clone();
        for (old, new) in unet.conv_shapes().iter().zip(target.conv_shapes()) {
            if old.in_channels == new.in_channels {
                continue;
            }
            let name = format!("{}.weight", old.name);
            let Some((_, w)) = tensors.iter_mut().find(|(n, _)| *n == name) else {
                bail!("the weights have no {name}")
            };
            let (out, channels, kh, kw) = w.dims4()?;
            let offset = channels - source_input;
            let mut parts = vec![w.narrow(1, 0, offset)?];
            for slot in &slots {
                parts.push(match slot {
                    Some(s) => w.narrow(1, offset + s, 3)?,
                    None => Tensor::zeros((out, 3, kh, kw), w.dtype(), w.device())?,
                });
            }
            *w = Tensor::cat(&parts, 1)?;
        }
        let info = ModelInfo {
            net: self.info.net.with_in_channels(features.in_channels()),
            features: features.clone(),
            ..self.info.clone()
        };
        info.validate()?;
        Ok(Pretrained { info, tensors })
    }

    /// These weights for the same network with output head `head` (the module docs say how). The same head
    /// returns them unchanged; a kernel head's weights cannot start another head.
    pub fn with_head(&self, head: Head) -> Result<Pretrained> {
        let from = self.info.net.head();
        if from == head {
            return Ok(self.clone());
        }
        let NetConfig::UNet(unet) = &self.info.net else {
            bail!("the patch MLP predicts colors; it has no other head")
        };
        let described = |h: Head| match h {
            Head::Direct => "colors".to_string(),
            Head::Kernel { size } => format!("{size}×{size} kernels"),
        };
        let Head::Kernel { size } = head else {
            bail!(
                "the weights predict {}; they cannot start a network that predicts colors (start from weights that \
                 predict colors, such as OIDN's)",
                described(from)
            )
        };
        if from != Head::Direct {
            bail!("the weights predict {}, not {size}×{size} kernels; keep their head", described(from))
        }
        let target = unet.with_head(head);
        target.validate()?;
        let (old, new) = (unet.conv_shapes(), target.conv_shapes());
        let (old_out, new_out) = (old.last().expect("an output layer"), new.last().expect("an output layer"));
        let dropped = [format!("{}.weight", old_out.name), format!("{}.bias", old_out.name)];
        let device = self.tensors.first().map_or(Device::Cpu, |(_, t)| t.device().clone());
        let mut tensors: Vec<(String, Tensor)> =
            self.tensors.iter().filter(|(n, _)| !dropped.contains(n)).cloned().collect();
        tensors.push((
            format!("{KERNEL_LAYER}.weight"),
            Tensor::zeros((new_out.out_channels, new_out.in_channels, 3, 3), DType::F32, &device)?,
        ));
        tensors.push((format!("{KERNEL_LAYER}.bias"), Tensor::zeros(new_out.out_channels, DType::F32, &device)?));
        tensors.sort_by(|a, b| a.0.cmp(&b.0));
        let info = ModelInfo { net: target.into(), ..self.info.clone() };
        info.validate()?;
        Ok(Pretrained { info, tensors })
    }

    /// The weights `(1 − t)·self + t·to`, tensor by tensor: interpolation in weight space between a network and
    /// one fine-tuned from it (Wortsman et al. 2022, "Robust fine-tuning of zero-shot models": WiSE-FT). `t = 0`
    /// is `self`, `t = 1` is `to`; in between, a model that keeps more of what `self` knew about inputs unlike
    /// the fine-tuning data. Both must be the same network taking the same features through the same
    /// transfer, with the same tensors by name and shape; an error names the first difference.
    pub fn interpolate(&self, to: &Pretrained, t: f64) -> Result<Pretrained> {
        if !t.is_finite() {
            bail!("the interpolation weight is {t}, not a finite number")
        }
        if self.info != to.info {
            bail!(
                "the two weights are different models: {} on {} against {} on {}",
                self.info.net.describe(),
                self.info.features,
                to.info.net.describe(),
                to.info.features
            )
        }
        let have: HashMap<&str, &Tensor> = to.tensors.iter().map(|(n, t)| (n.as_str(), t)).collect();
        let want: Vec<(&str, &[usize])> = self.tensors.iter().map(|(n, t)| (n.as_str(), t.dims())).collect();
        let theirs = match_by_name(&want, &have, ("the second weights", "the first model"))?;
        let tensors = self
            .tensors
            .iter()
            .map(|(name, a)| {
                let b = theirs[name.as_str()];
                let (a32, b32) = (a.to_dtype(DType::F32)?, b.to_dtype(DType::F32)?.to_device(a.device())?);
                Ok((name.clone(), (&a32 + ((&b32 - &a32)? * t)?)?))
            })
            .collect::<Result<Vec<_>>>()?;
        Ok(Pretrained { info: self.info.clone(), tensors })
    }

    /// These weights as a self-describing hush model file (what `hush train` writes as `model.safetensors`).
    pub fn to_safetensors(&self) -> Result<Vec<u8>> {
        serialize_weights(self.tensors.iter().map(|(n, t)| (n.as_str(), t)), &self.info)
    }

    /// Sets every variable of `varmap` (a network built for `self.info.net`) from these weights. Fails
    /// naming the first variable (in name order) that is missing here or has another shape, or the first
    /// tensor here the network does not have.
    pub fn load_into(&self, varmap: &VarMap) -> Result<()> {
        let vars = varmap.data().lock().map_err(|_| candle_core::Error::Msg("VarMap lock poisoned".into()))?;
        let have: HashMap<&str, &Tensor> = self.tensors.iter().map(|(n, t)| (n.as_str(), t)).collect();
        let want: Vec<(&str, &[usize])> = vars.iter().map(|(n, v)| (n.as_str(), v.dims())).collect();
        let matched = match_by_name(&want, &have, ("the initial weights", "the network"))?;
        for (name, var) in vars.iter() {
            var.set(&matched[name.as_str()].to_device(var.device())?.to_dtype(var.dtype())?)?;
        }
        Ok(())
    }
}

/// Pairs every tensor `want` names (with its shape) with the one of that name in `have`. Fails naming the
/// first (in name order) that `have` lacks or holds in another shape, then the first that `have` holds
/// beyond `want`; `sides` names `have` and `want` in those messages.
fn match_by_name<'a>(
    want: &[(&str, &[usize])],
    have: &HashMap<&str, &'a Tensor>,
    (have_name, want_name): (&str, &str),
) -> Result<HashMap<String, &'a Tensor>> {
    let mut sorted: Vec<&(&str, &[usize])> = want.iter().collect();
    sorted.sort_by_key(|(name, _)| *name);
    let mut matched = HashMap::new();
    for &&(name, dims) in &sorted {
        match have.get(name) {
            None => bail!("{have_name} have no tensor {name}, which {want_name} needs"),
            Some(t) if t.dims() != dims => {
                bail!("{name} is {:?} in {have_name} but {:?} in {want_name}", t.dims(), dims)
            }
            Some(t) => matched.insert(name.to_string(), *t),
        };
    }
    let mut extra: Vec<&str> = have.keys().copied().filter(|n| !matched.contains_key(*n)).collect();
    extra.sort();
    if let Some(first) = extra.first() {
        bail!("{have_name} hold {first}, which {want_name} does not have ({} such tensors)", extra.len())
    }
    Ok(matched)
}

#[cfg(test)]
mod tests {
    use candle_core::Module;
    use candle_nn::VarBuilder;

    use super::*;
    use crate::Net;
    use crate::unet::{UNetConfig, UNetKind, init_weights};
    use crate::weights::save_weights;

    fn model(features: &str, width: f64, seed: u64) -> (VarMap, ModelInfo) {
        let features = InputFeatures::parse(features).unwrap();
        let net: NetConfig = UNetConfig::new(UNetKind::UnetSmall, features.in_channels(), width).into();
        let varmap = VarMap::new();
        Net::new(VarBuilder::from_varmap(&varmap, DType::F32, &Device::Cpu), &net).unwrap();
        init_weights(&varmap, seed).unwrap();
        (varmap, ModelInfo { net, features, transfer: Transfer::Pu })
    }

    fn forward(varmap: &VarMap, info: &ModelInfo, x: &Tensor) -> Vec<f32> {
        let net = Net::new(VarBuilder::from_varmap(varmap, DType::F32, &Device::Cpu), &info.net).unwrap();
        net.forward(x).unwrap().flatten_all().unwrap().to_vec1().unwrap()
    }

    /// Adding features keeps what the network computes: an `alb,nrm` model adapted to `alb,nrm,spec`
    /// gives the same output whatever the new specular channels hold (their weights start at zero); the
    /// old features keep their weights. Dropping a feature, and loading into a different network, fail
    /// naming what does not match.
    #[test]
    fn adapting_features_keeps_the_function_and_mismatches_are_named() {
        let (source, info) = model("alb,nrm", 0.25, 3);
        let bytes = save_weights(&source, &info).unwrap();
        let pre = Pretrained::read(&bytes, &Device::Cpu).unwrap();
        assert_eq!(pre.info, info);
        let wider = pre.adapt(&InputFeatures::parse("alb,nrm,spec").unwrap()).unwrap();
        let (target, target_info) = model("alb,nrm,spec", 0.25, 9);
        assert_eq!(wider.info, target_info);
        wider.load_into(&target).unwrap();

        let x9 = Tensor::rand(0f32, 1f32, (1, 9, 16, 16), &Device::Cpu).unwrap();
        let spec = Tensor::rand(0f32, 1f32, (1, 3, 16, 16), &Device::Cpu).unwrap();
        let x12 = Tensor::cat(&[&x9, &spec], 1).unwrap();
        let (a, b) = (forward(&source, &info, &x9), forward(&target, &target_info, &x12));
        assert_eq!(a, b, "the adapted network computes what the source did");

        let err = pre.adapt(&InputFeatures::parse("nrm").unwrap()).unwrap_err().to_string();
        assert!(err.contains("drops albedo"), "{err}");
        let (other, _) = model("alb,nrm", 0.5, 1);
        let err = pre.load_into(&other).unwrap_err().to_string();
        assert!(err.contains("dec_conv0.weight is [3, 8, 3, 3] in the initial weights"), "{err}");
    }

    /// Interpolation: t = 0 is the first weights bit for bit, t = 1 the second (to rounding), t = 0.5 their
    /// mean; the file it writes reads back as the same model; different networks or features are refused.
    #[test]
    fn interpolation_runs_between_two_weights_of_one_network() {
        let (a, info) = model("alb,nrm", 0.25, 3);
        let (b, _) = model("alb,nrm", 0.25, 4);
        let read = |v: &VarMap| Pretrained::read(&save_weights(v, &info).unwrap(), &Device::Cpu).unwrap();
        let (pa, pb) = (read(&a), read(&b));
        let values = |p: &Pretrained| -> Vec<Vec<f32>> {
            p.tensors.iter().map(|(_, t)| t.flatten_all().unwrap().to_vec1().unwrap()).collect()
        };
        assert_eq!(values(&pa.interpolate(&pb, 0.0).unwrap()), values(&pa));
        for (x, y) in values(&pa.interpolate(&pb, 1.0).unwrap()).iter().flatten().zip(values(&pb).iter().flatten()) {
            assert!((x - y).abs() <= 1e-6 * y.abs().max(1.0), "{x} against {y}");
        }
        let half = pa.interpolate(&pb, 0.5).unwrap();
        for ((m, x), y) in
            values(&half).iter().flatten().zip(values(&pa).iter().flatten()).zip(values(&pb).iter().flatten())
        {
            assert!((m - (x + y) / 2.0).abs() <= 1e-6, "{m} is not the mean of {x} and {y}");
        }
        let back = Pretrained::read(&half.to_safetensors().unwrap(), &Device::Cpu).unwrap();
        assert_eq!(back.info, half.info);
        assert_eq!(values(&back), values(&half));

        let (wide, wide_info) = model("alb,nrm", 0.5, 4);
        let pw = Pretrained::read(&save_weights(&wide, &wide_info).unwrap(), &Device::Cpu).unwrap();
        let err = pa.interpolate(&pw, 0.5).unwrap_err().to_string();
        assert!(err.contains("different models"), "{err}");
        let (other, other_info) = model("alb", 0.25, 4);
        let po = Pretrained::read(&save_weights(&other, &other_info).unwrap(), &Device::Cpu).unwrap();
        assert!(pa.interpolate(&po, 0.5).unwrap_err().to_string().contains("different models"));
        assert!(pa.interpolate(&pb, f64::NAN).unwrap_err().to_string().contains("not a finite number"));
    }

    /// `diffuse` starts from the source's albedo weights, `specular` from zero.
    #[test]
    fn diffuse_starts_from_albedo() {
        let (source, info) = model("alb,nrm", 0.25, 5);
        let pre = Pretrained::read(&save_weights(&source, &info).unwrap(), &Device::Cpu).unwrap();
        let dsnn = pre.adapt(&InputFeatures::parse("diff,spec,nrm").unwrap()).unwrap();
        let w = |p: &Pretrained, name: &str| p.tensors.iter().find(|(n, _)| n == name).unwrap().1.clone();
        let (old, new) = (w(&pre, "enc_conv0.weight"), w(&dsnn, "enc_conv0.weight"));
        let slice = |t: &Tensor, s: usize| t.narrow(1, s, 3).unwrap().flatten_all().unwrap().to_vec1::<f32>().unwrap();
        assert_eq!(slice(&new, 0), slice(&old, 0), "color");
        assert_eq!(slice(&new, 3), slice(&old, 3), "diffuse from albedo");
        assert!(slice(&new, 6).iter().all(|v| *v == 0.0), "specular from zero");
        assert_eq!(slice(&new, 9), slice(&old, 6), "normal");
        // The skip into the last decoder level carries the input after 8 upsampled channels.
        let (old, new) = (w(&pre, "dec_conv1a.weight"), w(&dsnn, "dec_conv1a.weight"));
        assert_eq!(new.dims(), &[8, 8 + 12, 3, 3]);
        let head = |t: &Tensor| t.narrow(1, 0, 8).unwrap().flatten_all().unwrap().to_vec1::<f32>().unwrap();
        assert_eq!(head(&new), head(&old), "the upsampled features' weights");
        assert_eq!(slice(&new, 8), slice(&old, 8), "color in the skip");
        assert_eq!(slice(&new, 8 + 3), slice(&old, 8 + 3), "diffuse from albedo in the skip");
        assert!(slice(&new, 8 + 6).iter().all(|v| *v == 0.0));
        assert_eq!(slice(&new, 8 + 9), slice(&old, 8 + 6), "normal in the skip");

        // Beside the albedo itself, diffuse starts at zero: the albedo's weights must not count twice.
        let both = pre.adapt(&InputFeatures::parse("alb,diff,nrm").unwrap()).unwrap();
        let (old, new) = (w(&pre, "enc_conv0.weight"), w(&both, "enc_conv0.weight"));
        assert_eq!(slice(&new, 3), slice(&old, 3), "albedo");
        assert!(slice(&new, 6).iter().all(|v| *v == 0.0), "diffuse from zero beside the albedo");
    }
}
