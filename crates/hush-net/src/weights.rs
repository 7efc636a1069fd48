//! Self-describing weight files: safetensors bytes whose metadata holds the network configuration, the input
//! features and the transfer function as JSON under [`METADATA_KEY`]. No file I/O: bytes in, bytes out.

use std::borrow::Cow;
use std::collections::HashMap;

use candle_core::{DType, Device, Result, Tensor, bail};
use candle_nn::{VarBuilder, VarMap};
use safetensors::tensor::{Dtype, SafeTensors, View};
use serde::{Deserialize, Serialize};

use crate::input::InputFeatures;
use crate::net::{Net, NetConfig};
use crate::transfer::Transfer;

/// The safetensors metadata key holding [`ModelInfo`] as JSON.
pub const METADATA_KEY: &str = "hush.config";

/// Everything needed to rebuild a network and feed it: stored beside the weights.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ModelInfo {
    /// The network; files from before the patch MLP hold a bare U-Net configuration, which reads as one.
    pub net: NetConfig,
    pub features: InputFeatures,
    /// Transfer function applied to the color and the target.
    pub transfer: Transfer,
}

impl ModelInfo {
    /// Fails unless the network's input channels match the features.
    pub fn validate(&self) -> Result<()> {
        self.net.validate()?;
        if self.net.in_channels() != self.features.in_channels() {
            bail!(
                "network has {} input channels but features {} make {}",
                self.net.in_channels(),
                self.features,
                self.features.in_channels()
            )
        }
        if let Some(t) = self.net.kernel_linear()
            && t != self.transfer
        {
            bail!(
                "the network's kernels average through the inverse of the {t:?} transfer, but the model's input is \
                 in the {:?} transfer",
                self.transfer
            )
        }
        Ok(())
    }
}

/// An owned little-endian f32 buffer with a shape, for `safetensors::serialize`.
pub struct F32View {
    shape: Vec<usize>,
    bytes: Vec<u8>,
}

impl F32View {
    /// A copy of `t` as f32.
    pub fn of(t: &Tensor) -> Result<Self> {
        let values = t.to_dtype(DType::F32)?.flatten_all()?.to_vec1::<f32>()?;
        Ok(F32View { shape: t.dims().to_vec(), bytes: values.iter().flat_map(|v| v.to_le_bytes()).collect() })
    }
}

impl View for F32View {
    fn dtype(&self) -> Dtype {
        Dtype::F32
    }
    fn shape(&self) -> &[usize] {
        &self.shape
    }
    fn data(&self) -> Cow<'_, [u8]> {
        Cow::Borrowed(&self.bytes)
    }
    fn data_len(&self) -> usize {
        self.bytes.len()
    }
}

/// Serializes every variable of `varmap` as f32, with `info` as metadata. Tensor names are the VarMap's
/// (`enc_conv0.weight`, ...).
pub fn save_weights(varmap: &VarMap, info: &ModelInfo) -> Result<Vec<u8>> {
    let vars = varmap.data().lock().map_err(|_| candle_core::Error::Msg("VarMap lock poisoned".into()))?;
    serialize_weights(vars.iter().map(|(name, var)| (name.as_str(), var.as_tensor())), info)
}

/// Serializes named tensors as f32 in name order, with `info` as metadata.
pub(crate) fn serialize_weights<'a>(
    tensors: impl Iterator<Item = (&'a str, &'a Tensor)>,
    info: &ModelInfo,
) -> Result<Vec<u8>> {
    info.validate()?;
    let mut views = tensors.map(|(name, t)| Ok((name.to_string(), F32View::of(t)?))).collect::<Result<Vec<_>>>()?;
    views.sort_by(|a, b| a.0.cmp(&b.0));
    let json = serde_json::to_string(info).map_err(|e| candle_core::Error::Msg(format!("ModelInfo to JSON: {e}")))?;
    let metadata = HashMap::from([(METADATA_KEY.to_string(), json)]);
    Ok(safetensors::tensor::serialize(views, Some(metadata))?)
}

/// Sets every variable of `varmap` from `bytes`. Fails, naming them, if a variable is missing from the file,
/// has another shape, or the file holds tensors the map does not have (a different architecture).
pub fn load_weights(varmap: &VarMap, bytes: &[u8]) -> Result<()> {
    let vars = varmap.data().lock().map_err(|_| candle_core::Error::Msg("VarMap lock poisoned".into()))?;
    let device = match vars.values().next() {
        Some(v) => v.device().clone(),
        None => bail!("load_weights: the VarMap is empty; build the network first"),
    };
    let tensors = candle_core::safetensors::load_buffer(bytes, &device)?;
    let mut unexpected: Vec<&String> = tensors.keys().filter(|k| !vars.contains_key(*k)).collect();
    if !unexpected.is_empty() {
        unexpected.sort();
        bail!("load_weights: the file has tensors the network does not: {unexpected:?}")
    }
    let mut names: Vec<&String> = vars.keys().collect();
    names.sort();
    for name in names {
        let var = &vars[name];
        let Some(t) = tensors.get(name) else { bail!("load_weights: the file has no tensor {name}") };
        if t.dims() != var.dims() {
            bail!("load_weights: {name} has shape {:?} in the file but {:?} in the network", t.dims(), var.dims())
        }
        var.set(&t.to_dtype(var.dtype())?)?;
    }
    Ok(())
}

/// The [`ModelInfo`] stored in a weight file, `None` if it has none.
pub fn read_metadata(bytes: &[u8]) -> Result<Option<ModelInfo>> {
    let (_, metadata) = SafeTensors::read_metadata(bytes)?;
    let Some(json) = metadata.metadata().as_ref().and_then(|m| m.get(METADATA_KEY)) else {
        return Ok(None);
    };
    let info: ModelInfo = serde_json::from_str(json)
        .map_err(|e| candle_core::Error::Msg(format!("weight file metadata {METADATA_KEY} is not a ModelInfo: {e}")))?;
    Ok(Some(info))
}

/// Builds the network a self-describing weight file describes, with its weights, on `device` (f32).
pub fn load_model(bytes: &[u8], device: &Device) -> Result<(Net, ModelInfo)> {
    let Some(info) = read_metadata(bytes)? else {
        bail!("load_model: the weight file has no {METADATA_KEY} metadata; it was not written by hush")
    };
    info.validate()?;
    let tensors = candle_core::safetensors::load_buffer(bytes, device)?;
    let tensors: HashMap<String, Tensor> =
        tensors.into_iter().map(|(k, v)| Ok((k, v.to_dtype(DType::F32)?))).collect::<Result<_>>()?;
    let vb = VarBuilder::from_tensors(tensors, DType::F32, device);
    let net = Net::new(vb, &info.net)?;
    Ok((net, info))
}
