//! `hush export`: a hush model as OIDN's Tensor Archive, for OIDN's own runtime (`oidnDenoise -w`).

use anyhow::{Context, Result};
use clap::Args;

/// Arguments of `hush export`.
#[derive(Args, Debug)]
pub struct ExportArgs {
    /// A U-Net trained by `hush train` (`model.safetensors`).
    #[arg(long)]
    pub model: std::path::PathBuf,
    /// The TZA file to write (OIDN's layout: its layer order, f16 weights).
    #[arg(long)]
    pub out: std::path::PathBuf,
}

pub fn run(args: ExportArgs) -> Result<()> {
    let bytes =
        hush_pipeline::read_weight_file(&args.model).with_context(|| format!("reading {}", args.model.display()))?;
    let (net, info) = hush_net::load_model(&bytes, &candle_core::Device::Cpu)
        .with_context(|| format!("loading model {}", args.model.display()))?;
    let tza = net.export_tza().with_context(|| format!("exporting {}", args.model.display()))?;
    // OIDN's runtime tells a TZA's inputs by their count alone: color, albedo, normal in that order.
    if hush_net::oidn_features(info.net.in_channels()).ok().as_ref() != Some(&info.features) {
        anyhow::bail!(
            "exporting {}: OIDN's runtime takes color, albedo and normal (hdr, hdr,alb or hdr,alb,nrm), and this \
             model takes {}; use its .safetensors file with `hush denoise` or `hush eval` instead",
            args.model.display(),
            info.features
        );
    }
    hush_dataset::write_atomic(&args.out, |tmp| std::fs::write(tmp, &tza))
        .with_context(|| format!("writing {}", args.out.display()))?;
    eprintln!(
        "{}: {} on {} as TZA (OIDN's runtime applies its {} transfer for hdr input) → {}",
        args.model.display(),
        info.net.describe(),
        info.features,
        if info.transfer == hush_net::transfer::Transfer::Pu { "PU" } else { "own" },
        args.out.display()
    );
    Ok(())
}
