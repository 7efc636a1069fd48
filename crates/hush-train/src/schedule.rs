//! Learning-rate schedules (thesis §4.4, eqs. 4.17–4.22): the learning rate as a function of the epoch.
//! Each is a closed form of `(base_lr, epoch, epochs)`, so a resumed run needs no schedule state.

use serde::{Deserialize, Serialize};

/// How the learning rate changes from epoch to epoch. Epochs are 1-based, as in the thesis (μ(1) = μ_init);
/// `base` below is the configured learning rate.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Schedule {
    /// Eq. 4.18: μ(e) = c, with c = `base`. The thesis's final choice (Adam at 1e-4).
    Constant,
    /// Step decay, a lambda schedule (eq. 4.19) with λ(e) = γ^⌊(e − 1) / every⌋: the rate drops by `gamma`
    /// every `every` epochs (PyTorch's `StepLR`).
    Step { every: usize, gamma: f64 },
    /// Eq. 4.19 with custom factors: μ(e) = μ_init · λ(e), λ(e) = `factors[e − 1]`, the last factor
    /// repeated after the list ends (PyTorch's `LambdaLR`).
    Lambda { factors: Vec<f64> },
    /// Eqs. 4.20–4.21: μ(1) = μ_init, μ(e + 1) = γ · μ(e), i.e. μ(e) = μ_init · γ^(e − 1).
    Exponential { gamma: f64 },
    /// Cosine annealing, eq. 4.22: μ(e) = μ_min + ½(μ_max − μ_min)(1 + cos(π T_cur / T_max)) with
    /// μ_max = `base`, T_cur = e − 1 and T_max = `t_max` epochs (0: the whole run).
    Cosine { min_lr: f64, t_max: usize },
    /// SGDR (Loshchilov and Hutter): eq. 4.22 where T_cur restarts at 0 after each cycle; the first cycle
    /// lasts `t0` epochs, each next one `t_mult` times longer (PyTorch's `CosineAnnealingWarmRestarts`).
    CosineRestarts { t0: usize, t_mult: usize, min_lr: f64 },
    /// Open Image Denoise's one-cycle policy (PyTorch's `OneCycleLR`, cosine): from `base / div` up to
    /// `base` (the maximum) over the first `pct_start` of the run, then down to `base / div / final_div`.
    /// OIDN: pct_start 0.15, div 25, final_div 1e4, and max_lr 3.125e-6 × batch size.
    OneCycle { pct_start: f64, div: f64, final_div: f64 },
}

impl Schedule {
    /// OIDN's one-cycle parameters.
    pub fn one_cycle() -> Self {
        Schedule::OneCycle { pct_start: 0.15, div: 25.0, final_div: 1e4 }
    }

    /// Parses a schedule by name with defaults: `constant`, `step` (×0.5 every 10% of the run, as
    /// `step:every:gamma` to choose), `lambda:f1,f2,...`, `exponential` (γ 0.99, or `exponential:γ`),
    /// `cosine` (to 0 over the run), `sgdr` / `cosine_restarts` (T_0 = 10% of the run, T_mult 2, or
    /// `sgdr:t0:t_mult`), `one_cycle` / `onecycle` (OIDN's). `epochs` sizes the defaults.
    pub fn parse(spec: &str, epochs: usize) -> Option<Self> {
        let mut parts = spec.split(':');
        let name = parts.next()?.trim();
        let args: Vec<&str> = parts.collect();
        let num = |i: usize| -> Option<f64> { args.get(i)?.trim().parse().ok() };
        let tenth = (epochs / 10).max(1);
        Some(match name {
            "constant" | "const" => Schedule::Constant,
            "step" => Schedule::Step {
                every: num(0).map_or(Some(tenth), |v| (v >= 1.0).then_some(v as usize))?,
                gamma: num(1).unwrap_or(0.5),
            },
            "lambda" => {
                let factors: Option<Vec<f64>> = args.first()?.split(',').map(|f| f.trim().parse().ok()).collect();
                Schedule::Lambda { factors: factors? }
            }
            "exponential" | "exp" => Schedule::Exponential { gamma: num(0).unwrap_or(0.99) },
            "cosine" | "csa" => Schedule::Cosine { min_lr: num(0).unwrap_or(0.0), t_max: 0 },
            "sgdr" | "cosine_restarts" | "car" => Schedule::CosineRestarts {
                t0: num(0).map_or(tenth, |v| v as usize),
                t_mult: num(1).map_or(2, |v| v as usize),
                min_lr: 0.0,
            },
            "one_cycle" | "onecycle" => Schedule::one_cycle(),
            _ => return None,
        })
    }

    /// Checks the parameters.
    pub fn validate(&self) -> Result<(), String> {
        let ok = match self {
            Schedule::Constant => true,
            Schedule::Step { every, gamma } => *every > 0 && *gamma > 0.0 && gamma.is_finite(),
            Schedule::Lambda { factors } => !factors.is_empty() && factors.iter().all(|f| f.is_finite() && *f >= 0.0),
            Schedule::Exponential { gamma } => *gamma > 0.0 && gamma.is_finite(),
            Schedule::Cosine { min_lr, .. } => *min_lr >= 0.0 && min_lr.is_finite(),
            Schedule::CosineRestarts { t0, t_mult, min_lr } => *t0 > 0 && *t_mult > 0 && *min_lr >= 0.0,
            Schedule::OneCycle { pct_start, div, final_div } => {
                *pct_start > 0.0 && *pct_start < 1.0 && *div > 0.0 && *final_div > 0.0
            }
        };
        if ok { Ok(()) } else { Err(format!("learning-rate schedule parameters out of range: {self:?}")) }
    }

    /// The learning rate of 1-based `epoch` of a run of `epochs` epochs.
    pub fn lr(&self, base: f64, epoch: usize, epochs: usize) -> f64 {
        let e = epoch.max(1);
        let cosine = |min: f64, max: f64, t_cur: f64, t_max: f64| {
            min + 0.5 * (max - min) * (1.0 + (std::f64::consts::PI * t_cur / t_max).cos())
        };
        match self {
            Schedule::Constant => base,
            Schedule::Step { every, gamma } => base * gamma.powi(((e - 1) / every.max(&1)) as i32),
            Schedule::Lambda { factors } => base * factors.get(e - 1).or(factors.last()).copied().unwrap_or(1.0),
            Schedule::Exponential { gamma } => base * gamma.powi((e - 1) as i32),
            Schedule::Cosine { min_lr, t_max } => {
                let t_max = if *t_max == 0 { epochs.max(1) } else { *t_max };
                cosine(*min_lr, base, (e - 1) as f64, t_max as f64)
            }
            Schedule::CosineRestarts { t0, t_mult, min_lr } => {
                let (mut t_cur, mut t_i) = (e - 1, (*t0).max(1));
                while t_cur >= t_i {
                    t_cur -= t_i;
                    t_i *= (*t_mult).max(1);
                }
                cosine(*min_lr, base, t_cur as f64, t_i as f64)
            }
            Schedule::OneCycle { pct_start, div, final_div } => {
                // PyTorch's OneCycleLR with anneal_strategy="cos" and three_phase=False, where "step" i is
                // the 0-based epoch and total_steps the number of epochs.
                let initial = base / div;
                let min = initial / final_div;
                let i = (e - 1) as f64;
                let total = epochs.max(1) as f64;
                let up_end = pct_start * total - 1.0;
                let down_end = total - 1.0;
                // `end + (start - end) / 2 · (1 + cos(π · pct))`, PyTorch's `_annealing_cos`.
                let anneal = |start: f64, end: f64, pct: f64| cosine(end, start, pct, 1.0);
                if up_end > 0.0 && i <= up_end {
                    anneal(initial, base, i / up_end)
                } else if down_end > up_end.max(0.0) {
                    let from = up_end.max(0.0);
                    anneal(base, min, ((i - from) / (down_end - from)).clamp(0.0, 1.0))
                } else {
                    base
                }
            }
        }
    }
}
