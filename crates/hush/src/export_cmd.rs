//! `hush export`: a hush model as OIDN's Tensor Archive, for OIDN's own runtime (`oidnDenoise -w`).

use anyhow::{Context, Result, bail};
use clap::Args;
use hush_dataset::Image;
use hush_eval::external::{Input, Outcome, run_oidn_with_weights, venv_python};

/// Arguments of `hush export`.
#[derive(Args, Debug)]
pub struct ExportArgs {
    /// A U-Net trained by `hush train` (`model.safetensors`).
    #[arg(long)]
    pub model: std::path::PathBuf,
    /// The TZA file to write (OIDN's layout: its layer order, f16 weights).
    #[arg(long)]
    pub out: std::path::PathBuf,
    /// Then denoise this noisy render with hush (the model) and with OIDN's own runtime (the written file,
    /// through pyoidn in the baselines venv of `cargo xtask baselines setup`), and fail unless they agree
    /// within 45 dB PSNR. A `hush render` EXR (its layers give the auxiliary images) or a dataset's
    /// `<view>_<spp>.hdr.exr` (with the `.alb.exr` and `.nrm.exr` beside it).
    #[arg(long)]
    pub check: Option<std::path::PathBuf>,
}

/// The least agreement between hush and OIDN's runtime on the same weights and input that `--check` accepts
/// (OIDN's runtime computes in f16 or f32 with other summation orders; the tests measure above 100 dB).
const CHECK_MIN_PSNR: f64 = 45.0;

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
    if let Some(input) = &args.check {
        check(&args, input, &bytes, &info.features, &tza)?;
    }
    Ok(())
}

/// The color and the auxiliary images `features` names of a noisy render: the layers of a `hush render`
/// EXR, or a dataset's `.hdr.exr` with the `.alb.exr` / `.nrm.exr` files beside it.
fn read_input(path: &std::path::Path, features: &hush_net::InputFeatures) -> Result<(Image, Vec<Image>)> {
    let name = path.to_string_lossy();
    let exr = hush_dataset::read_exr(path).with_context(|| format!("reading {}", path.display()))?;
    let color = exr.layer("").with_context(|| format!("reading the color of {}", path.display()))?;
    let mut aux = Vec::new();
    for &f in &features.aux {
        let image = if let Some(layer) = crate::denoise_cmd::feature_layer(&exr, f) {
            layer?
        } else if let Some(stem) = name.strip_suffix(".hdr.exr") {
            let beside = std::path::PathBuf::from(format!("{stem}.{}.exr", f.short_name()));
            hush_dataset::read_rgb(&beside).with_context(|| {
                format!("--check {}: the model takes {}; reading {}", path.display(), f.long_name(), beside.display())
            })?
        } else {
            bail!(
                "--check {}: the model takes {} and the file has no '{}' layer (give a `hush render` EXR or a \
                 dataset's .hdr.exr)",
                path.display(),
                f.long_name(),
                f.long_name()
            );
        };
        aux.push(image);
    }
    Ok((color, aux))
}

/// `--check`: the model run by hush and the written TZA run by OIDN's runtime agree on `input`.
fn check(
    args: &ExportArgs,
    input: &std::path::Path,
    model: &[u8],
    features: &hush_net::InputFeatures,
    tza: &[u8],
) -> Result<()> {
    let (color, aux) = read_input(input, features)?;
    let model = hush_pipeline::Denoiser::from_bytes(model, false)?;
    let refs: Vec<&Image> = aux.iter().collect();
    let ours = model.denoise(&color, &refs)?;
    let inputs = [Input { color: &color, albedo: aux.first(), normal: aux.get(1) }];
    let theirs = match run_oidn_with_weights(&inputs, tza, &venv_python(), 1)? {
        Outcome::Done { images, .. } => images.into_iter().next().context("OIDN's runtime returned no image")?,
        Outcome::Skipped { reason, install } => {
            bail!("--check needs OIDN's runtime: {reason}; install it with `{install}`")
        }
    };
    let agreement = hush_eval::psnr(&theirs, &ours)?;
    // On standard output, for the caller that records it (`cargo xtask train-default` writes it on the card).
    println!(
        "{}: OIDN's runtime on {} and hush on {} agree to {agreement:.1} dB PSNR on {} ({}×{})",
        if agreement >= CHECK_MIN_PSNR { "check passed" } else { "check FAILED" },
        args.out.display(),
        args.model.display(),
        input.display(),
        color.width,
        color.height
    );
    if agreement < CHECK_MIN_PSNR {
        bail!(
            "OIDN's runtime does not reproduce hush's output on the exported file ({agreement:.1} dB < \
             {CHECK_MIN_PSNR} dB)"
        );
    }
    Ok(())
}
