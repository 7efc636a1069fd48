//! Optimizers over Candle variables whose state can be saved and restored exactly: Adam (with decoupled
//! weight decay as AdamW) and SGD (with momentum). Candle's own `AdamW` keeps its moments private, so a
//! resumed run could not continue where it stopped.

use std::collections::HashMap;

use candle_core::backprop::GradStore;
use candle_core::{Result, Tensor, Var, bail};
use candle_nn::VarMap;
use serde::{Deserialize, Serialize};

/// Which optimizer, with its hyperparameters (the learning rate comes from the schedule, per step).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum OptimizerConfig {
    /// Adam (Kingma and Ba), thesis §4.4.1: per-weight step sizes from running estimates of the first and
    /// second moments of the gradient. `weight_decay > 0` makes it AdamW (decay decoupled from the
    /// gradient: `w ← w·(1 − lr·weight_decay)` before the Adam update); 0 is plain Adam.
    Adam { beta1: f64, beta2: f64, eps: f64, weight_decay: f64 },
    /// Stochastic gradient descent, thesis eqs. 4.15–4.16, with PyTorch's momentum: `b ← momentum·b + g`,
    /// `w ← w − lr·b` (momentum 0 is plain SGD). `weight_decay` adds `weight_decay·w` to the gradient.
    Sgd { momentum: f64, weight_decay: f64 },
}

impl OptimizerConfig {
    /// Adam with PyTorch's defaults (β1 0.9, β2 0.999, ε 1e-8) and no weight decay: the thesis's optimizer.
    pub fn adam() -> Self {
        OptimizerConfig::Adam { beta1: 0.9, beta2: 0.999, eps: 1e-8, weight_decay: 0.0 }
    }

    /// SGD with momentum 0.9 (0 for the thesis's plain SGD).
    pub fn sgd(momentum: f64) -> Self {
        OptimizerConfig::Sgd { momentum, weight_decay: 0.0 }
    }

    /// `adam`, `adamw` (Adam with weight decay 0.01, PyTorch's AdamW default), `sgd` (no momentum) or
    /// `sgd_momentum` (0.9).
    pub fn parse(name: &str) -> Option<Self> {
        Some(match name {
            "adam" => OptimizerConfig::adam(),
            "adamw" => OptimizerConfig::Adam { beta1: 0.9, beta2: 0.999, eps: 1e-8, weight_decay: 0.01 },
            "sgd" => OptimizerConfig::sgd(0.0),
            "sgd_momentum" | "sgd-momentum" => OptimizerConfig::sgd(0.9),
            _ => return None,
        })
    }

    /// Names of the per-variable state tensors.
    fn slots(&self) -> &'static [&'static str] {
        match self {
            OptimizerConfig::Adam { .. } => &["m", "v"],
            OptimizerConfig::Sgd { momentum, .. } if *momentum != 0.0 => &["momentum"],
            OptimizerConfig::Sgd { .. } => &[],
        }
    }

    pub fn validate(&self) -> std::result::Result<(), String> {
        let ok = match *self {
            OptimizerConfig::Adam { beta1, beta2, eps, weight_decay } => {
                (0.0..1.0).contains(&beta1)
                    && (0.0..1.0).contains(&beta2)
                    && eps > 0.0
                    && weight_decay >= 0.0
                    && weight_decay.is_finite()
            }
            OptimizerConfig::Sgd { momentum, weight_decay } => {
                (0.0..1.0).contains(&momentum) && weight_decay >= 0.0 && weight_decay.is_finite()
            }
        };
        if ok { Ok(()) } else { Err(format!("optimizer parameters out of range: {self:?}")) }
    }
}

/// An optimizer over named variables. Its state (the step count and, per variable, Adam's moments or
/// SGD's momentum buffer) comes out as named tensors ([`Optimizer::state`]) and goes back in
/// ([`Optimizer::load_state`]) bit for bit.
pub struct Optimizer {
    cfg: OptimizerConfig,
    vars: Vec<(String, Var)>,
    /// Per variable, one tensor per slot of `cfg.slots()`.
    state: Vec<Vec<Tensor>>,
    step: u64,
}

impl std::fmt::Debug for Optimizer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Optimizer")
            .field("cfg", &self.cfg)
            .field("vars", &self.vars.len())
            .field("step", &self.step)
            .finish()
    }
}

impl Optimizer {
    /// An optimizer over `vars`, its state zero.
    pub fn new(cfg: OptimizerConfig, vars: Vec<(String, Var)>) -> Result<Self> {
        if let Err(m) = cfg.validate() {
            bail!("{m}")
        }
        let state = vars
            .iter()
            .map(|(_, v)| cfg.slots().iter().map(|_| v.as_tensor().zeros_like()).collect::<Result<Vec<_>>>())
            .collect::<Result<_>>()?;
        Ok(Optimizer { cfg, vars, state, step: 0 })
    }

    /// An optimizer over every variable of `varmap`, sorted by name.
    pub fn for_varmap(cfg: OptimizerConfig, varmap: &VarMap) -> Result<Self> {
        let mut vars: Vec<(String, Var)> = {
            let data = varmap.data().lock().map_err(|_| candle_core::Error::Msg("VarMap lock poisoned".into()))?;
            data.iter().map(|(k, v)| (k.clone(), v.clone())).collect()
        };
        vars.sort_by(|a, b| a.0.cmp(&b.0));
        Optimizer::new(cfg, vars)
    }

    /// An optimizer over the variables of `varmap` whose layer (the name before its first `.`) is among
    /// `layers`, sorted by name; every variable when `layers` is empty. A layer with no variable is an
    /// error that lists the layers there are.
    pub fn for_layers(cfg: OptimizerConfig, varmap: &VarMap, layers: &[String]) -> Result<Self> {
        let all = Optimizer::for_varmap(cfg, varmap)?;
        if layers.is_empty() {
            return Ok(all);
        }
        let layer_of = |name: &str| name.split('.').next().unwrap_or(name).to_string();
        for layer in layers {
            if !all.vars.iter().any(|(name, _)| &layer_of(name) == layer) {
                let mut known: Vec<String> = all.vars.iter().map(|(n, _)| layer_of(n)).collect();
                known.dedup();
                bail!("no layer {layer} in the network to train; its layers are {}", known.join(", "))
            }
        }
        let vars = all.vars.into_iter().filter(|(name, _)| layers.contains(&layer_of(name))).collect();
        Optimizer::new(all.cfg, vars)
    }

    pub fn config(&self) -> &OptimizerConfig {
        &self.cfg
    }

    /// Updates done so far.
    pub fn step_count(&self) -> u64 {
        self.step
    }

    /// The variables, by name.
    pub fn vars(&self) -> &[(String, Var)] {
        &self.vars
    }

    /// One update with learning rate `lr`; every gradient is first multiplied by `grad_scale` (gradient
    /// clipping; 1 leaves them untouched). Variables without a gradient are left alone.
    pub fn step(&mut self, grads: &GradStore, lr: f64, grad_scale: f64) -> Result<()> {
        self.step += 1;
        let t = self.step as i32;
        for ((_, var), state) in self.vars.iter().zip(self.state.iter_mut()) {
            let Some(g) = grads.get(var) else { continue };
            let scaled;
            let g = if grad_scale == 1.0 {
                g
            } else {
                scaled = (g * grad_scale)?;
                &scaled
            };
            match self.cfg {
                // The same operations in the same order as candle_nn::AdamW, so that both agree bit for bit.
                OptimizerConfig::Adam { beta1, beta2, eps, weight_decay } => {
                    let scale_m = 1f64 / (1f64 - beta1.powi(t));
                    let scale_v = 1f64 / (1f64 - beta2.powi(t));
                    let next_m = ((&state[0] * beta1)? + (g * (1.0 - beta1))?)?;
                    let next_v = ((&state[1] * beta2)? + (g.sqr()? * (1.0 - beta2))?)?;
                    let m_hat = (&next_m * scale_m)?;
                    let v_hat = (&next_v * scale_v)?;
                    let theta = (var.as_tensor() * (1f64 - lr * weight_decay))?;
                    let adjusted = (m_hat / (v_hat.sqrt()? + eps)?)?;
                    var.set(&(theta - (adjusted * lr)?)?)?;
                    state[0] = next_m;
                    state[1] = next_v;
                }
                OptimizerConfig::Sgd { momentum, weight_decay } => {
                    let decayed;
                    let g = if weight_decay == 0.0 {
                        g
                    } else {
                        decayed = (g + (var.as_tensor() * weight_decay)?)?;
                        &decayed
                    };
                    let update = if momentum == 0.0 {
                        g.clone()
                    } else {
                        let b = ((&state[0] * momentum)? + g)?;
                        state[0] = b.clone();
                        b
                    };
                    var.set(&(var.as_tensor() - (update * lr)?)?)?;
                }
            }
        }
        Ok(())
    }

    /// The state as named tensors, `optim.<slot>.<variable>` (e.g. `optim.m.enc_conv0.weight`).
    pub fn state(&self) -> Vec<(String, Tensor)> {
        let slots = self.cfg.slots();
        self.vars
            .iter()
            .zip(&self.state)
            .flat_map(|((name, _), s)| {
                slots.iter().zip(s).map(move |(slot, t)| (format!("optim.{slot}.{name}"), t.clone()))
            })
            .collect()
    }

    /// Restores the state written by [`Optimizer::state`] after `step` updates. Fails, naming it, if a
    /// tensor is missing or has another shape (an optimizer of another kind or another network).
    pub fn load_state(&mut self, step: u64, tensors: &HashMap<String, Tensor>) -> Result<()> {
        let slots = self.cfg.slots();
        for ((name, var), state) in self.vars.iter().zip(self.state.iter_mut()) {
            for (slot, s) in slots.iter().zip(state.iter_mut()) {
                let key = format!("optim.{slot}.{name}");
                let Some(t) = tensors.get(&key) else {
                    bail!("the optimizer state has no {key}: it was saved by another optimizer ({:?} now)", self.cfg)
                };
                if t.dims() != var.dims() {
                    bail!("optimizer state {key} has shape {:?} but the variable has {:?}", t.dims(), var.dims())
                }
                *s = t.to_dtype(var.dtype())?.to_device(var.device())?;
            }
        }
        self.step = step;
        Ok(())
    }
}
