//! `hush blend`: the weights `(1 − t)·from + t·to` of a network and one fine-tuned from it, as a hush model.

use anyhow::{Context, Result};
use clap::Args;

/// Arguments of `hush blend`.
#[derive(Args, Debug)]
pub struct BlendArgs {
    /// The weights at t = 0: a .tza or .safetensors file, or `oidn` for OIDN's official weights of the
    /// features `--to` takes.
    #[arg(long)]
    pub from: std::path::PathBuf,
    /// The weights at t = 1: the same network fine-tuned (`hush train --init ...`), .safetensors or .tza.
    #[arg(long)]
    pub to: std::path::PathBuf,
    /// t: 0 gives `--from`, 1 gives `--to`.
    #[arg(long)]
    pub t: f64,
    /// The model to write (.safetensors, self-describing like `hush train`'s).
    #[arg(long)]
    pub out: std::path::PathBuf,
}

pub fn run(args: BlendArgs) -> Result<()> {
    let blended = hush_pipeline::train::blend(&args.from, &args.to, args.t)?;
    let bytes = blended.to_safetensors().context("serializing the blended weights")?;
    hush_dataset::write_atomic(&args.out, |tmp| std::fs::write(tmp, &bytes))
        .with_context(|| format!("writing {}", args.out.display()))?;
    eprintln!(
        "{} × {} + {} × {} ({} on {}) → {}",
        1.0 - args.t,
        args.from.display(),
        args.t,
        args.to.display(),
        blended.info.net.describe(),
        blended.info.features,
        args.out.display()
    );
    Ok(())
}
