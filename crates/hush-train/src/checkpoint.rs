//! Checkpoints: one safetensors blob with the weights (under their usual names, with the model metadata
//! of [`hush_net::save_weights`], so `hush denoise` can load a checkpoint as it is), the optimizer's state
//! beside them (`optim.<slot>.<name>`) and the training state (step, epoch, crops drawn, best test loss,
//! the configuration) as JSON metadata. Everything a run needs to continue exactly.

use std::collections::HashMap;

use candle_core::Device;
use candle_nn::VarMap;
use hush_net::{F32View, METADATA_KEY};
use safetensors::tensor::SafeTensors;
use serde::{Deserialize, Serialize};

use crate::{Optimizer, Result, TrainConfig, TrainError};

/// The safetensors metadata key holding [`TrainState`] as JSON.
pub const STATE_KEY: &str = "hush.train_state";

/// Where a run stands at the end of an epoch.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TrainState {
    /// Optimizer steps completed.
    pub step: usize,
    /// Epochs completed.
    pub epoch: usize,
    /// Crops drawn so far: the sampler's whole state (its random stream is counter-based).
    pub crops_drawn: u64,
    /// Updates the optimizer has done (Adam's bias correction depends on it).
    pub optimizer_steps: u64,
    /// The lowest test loss so far and its epoch.
    pub best: Option<(usize, f64)>,
    /// The configuration of the run that wrote the checkpoint.
    pub config: TrainConfig,
}

fn to_json<T: Serialize>(v: &T) -> Result<String> {
    serde_json::to_string(v).map_err(|e| TrainError::Config(format!("cannot serialize the training state: {e}")))
}

/// Serializes weights, optimizer state and training state into one blob.
pub(crate) fn save_checkpoint(varmap: &VarMap, opt: &Optimizer, state: &TrainState) -> Result<Vec<u8>> {
    let info = state.config.model_info();
    let mut views = Vec::new();
    {
        let vars = varmap.data().lock().map_err(|_| candle_core::Error::Msg("VarMap lock poisoned".into()))?;
        for (name, var) in vars.iter() {
            views.push((name.clone(), F32View::of(var.as_tensor())?));
        }
    }
    for (name, t) in opt.state() {
        views.push((name, F32View::of(&t)?));
    }
    views.sort_by(|a, b| a.0.cmp(&b.0));
    let metadata =
        HashMap::from([(METADATA_KEY.to_string(), to_json(&info)?), (STATE_KEY.to_string(), to_json(state)?)]);
    Ok(safetensors::tensor::serialize(views, Some(metadata)).map_err(candle_core::Error::from)?)
}

/// The training state of a checkpoint; `None` for a weights file without one (e.g. `model.safetensors`).
pub fn read_train_state(bytes: &[u8]) -> Result<Option<TrainState>> {
    let (_, metadata) = SafeTensors::read_metadata(bytes).map_err(candle_core::Error::from)?;
    let Some(json) = metadata.metadata().as_ref().and_then(|m| m.get(STATE_KEY)) else { return Ok(None) };
    let state = serde_json::from_str(json)
        .map_err(|e| TrainError::Config(format!("the checkpoint's {STATE_KEY} is not a training state: {e}")))?;
    Ok(Some(state))
}

/// Restores weights and optimizer state from `bytes` and returns the training state. The checkpoint must
/// come from a run with the same network and features (the message names both otherwise).
pub(crate) fn load_checkpoint(
    bytes: &[u8],
    cfg: &TrainConfig,
    varmap: &VarMap,
    opt: &mut Optimizer,
    device: &Device,
) -> Result<TrainState> {
    let Some(state) = read_train_state(bytes)? else {
        return Err(TrainError::Config(
            "cannot resume: the file is a weights file, not a checkpoint (it carries no training state)".into(),
        ));
    };
    let (stored, now) = (state.config.model_info(), cfg.model_info());
    if stored != now {
        return Err(TrainError::Config(format!(
            "cannot resume: the checkpoint was trained with the network {} on features {}, but this run asks for \
             the network {} on features {}",
            stored.net.describe(),
            stored.features,
            now.net.describe(),
            now.features
        )));
    }
    if state.config.optimizer != cfg.optimizer {
        return Err(TrainError::Config(format!(
            "cannot resume: the checkpoint's optimizer is {:?} but this run asks for {:?}",
            state.config.optimizer, cfg.optimizer
        )));
    }
    let tensors = candle_core::safetensors::load_buffer(bytes, device)?;
    {
        let vars = varmap.data().lock().map_err(|_| candle_core::Error::Msg("VarMap lock poisoned".into()))?;
        for (name, var) in vars.iter() {
            let Some(t) = tensors.get(name) else {
                return Err(TrainError::Config(format!("cannot resume: the checkpoint has no tensor {name}")));
            };
            if t.dims() != var.dims() {
                return Err(TrainError::Config(format!(
                    "cannot resume: {name} has shape {:?} in the checkpoint but {:?} in the network",
                    t.dims(),
                    var.dims()
                )));
            }
            var.set(&t.to_dtype(var.dtype())?)?;
        }
    }
    opt.load_state(state.optimizer_steps, &tensors)?;
    Ok(state)
}
