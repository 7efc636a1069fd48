//! Weight-space interpolation between a network and one fine-tuned from it (`hush blend`): the model
//! `(1 − t)·from + t·to`, which keeps more of what `from` knew about inputs unlike the fine-tuning data
//! (WiSE-FT, Wortsman et al. 2022). The result is the same network as both, so it runs, exports to TZA and
//! costs exactly what either does.

use std::path::Path;

use anyhow::{Context, Result};
use hush_net::Pretrained;

use super::options::read_trained;

/// The weights `(1 − t)·from + t·to`, each a hush model or TZA file, or `oidn` for OIDN's official weights
/// (`from`: those of `to`'s features). `from` is first made the network `to` is as `hush train --init`
/// makes it (more input features, another output head: [`Pretrained::adapt`], [`Pretrained::with_head`]),
/// so that a model fine-tuned with new features or kernel prediction interpolates from where its training
/// started. Errors name the option, the file and what does not match.
pub fn blend(from: &Path, to: &Path, t: f64) -> Result<Pretrained> {
    let (to_weights, _) = read_trained(to, None, "--to")?;
    let (from_weights, _) = read_trained(from, Some(&to_weights.info.features), "--from")?;
    let from_weights = from_weights
        .adapt(&to_weights.info.features)
        .and_then(|w| w.with_head(to_weights.info.net.head()))
        .with_context(|| format!("--from {} cannot start --to {}", from.display(), to.display()))?;
    from_weights
        .interpolate(&to_weights, t)
        .with_context(|| format!("interpolating {} towards {}", from.display(), to.display()))
}
