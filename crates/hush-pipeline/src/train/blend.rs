//! Weight-space interpolation between a network and one fine-tuned from it (`hush blend`): the model
//! `(1 − t)·from + t·to`, which keeps more of what `from` knew about inputs unlike the fine-tuning data
//! (WiSE-FT, Wortsman et al. 2022). The result is the same network as both, so it runs, exports to TZA and
//! costs exactly what either does.

use std::path::Path;

use anyhow::{Context, Result};
use hush_net::Pretrained;

use super::options::read_init;

/// The weights `(1 − t)·from + t·to`. `to` is a hush model or TZA file; `from` is one too, or `oidn` for
/// OIDN's official weights of `to`'s features. Errors name the file and what does not match.
pub fn blend(from: &Path, to: &Path, t: f64) -> Result<Pretrained> {
    let to_bytes = crate::read_weight_file(to).with_context(|| format!("reading {}", to.display()))?;
    let to_weights = Pretrained::read(&to_bytes, &candle_core::Device::Cpu)
        .with_context(|| format!("{}: not a hush model or TZA weights", to.display()))?;
    let (from_weights, _) = read_init(from, Some(&to_weights.info.features))?;
    from_weights
        .interpolate(&to_weights, t)
        .with_context(|| format!("interpolating {} towards {}", from.display(), to.display()))
}
