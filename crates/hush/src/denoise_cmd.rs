//! `hush denoise`: one image through a trained model (or OIDN's weights), its features from the flags or
//! from the layers of a `hush render` EXR.

use anyhow::{Context, Result, bail};
use hush_dataset::{ExrImage, Image, read_exr, read_pfm, read_rgb, write_pfm, write_rgb};
use hush_net::{Feature, InputFeatures};
use hush_pipeline::Denoiser;
use hush_pipeline::shipped::{Inference, default_for};

use crate::cli::DenoiseArgs;

/// The layer of a `hush render` EXR that holds a feature.
fn layer_name(f: Feature) -> &'static str {
    f.long_name()
}

/// The layer of a `hush render` EXR that holds feature `f`, where it has one.
pub(crate) fn feature_layer(exr: &ExrImage, f: Feature) -> Option<Result<Image>> {
    let prefix = format!("{}.", layer_name(f));
    exr.channels.keys().any(|k| k.starts_with(&prefix)).then(|| Ok(exr.layer(layer_name(f))?))
}

/// Whether `path` names a PFM file (OIDN's format), by its extension; anything else is read as EXR.
fn is_pfm(path: &std::path::Path) -> bool {
    path.extension().is_some_and(|e| e.eq_ignore_ascii_case("pfm"))
}

/// An RGB image from an EXR or a PFM file.
fn read_image(path: &std::path::Path) -> Result<Image> {
    Ok(if is_pfm(path) { read_pfm(path)? } else { read_rgb(path)? })
}

pub fn run(args: DenoiseArgs) -> Result<()> {
    // A PFM color is one RGB image (its features come from the flags); an EXR may carry them as layers.
    let (color, exr): (Image, Option<ExrImage>) = if is_pfm(&args.color) {
        (read_pfm(&args.color)?, None)
    } else {
        let exr = read_exr(&args.color)?;
        let color = exr.layer("").with_context(|| format!("reading the color of {}", args.color.display()))?;
        (color, Some(exr))
    };
    let given = |f: Feature| match f {
        Feature::Albedo => &args.albedo,
        Feature::Normal => &args.normal,
        Feature::Diffuse => &args.diffuse,
        Feature::Specular => &args.specular,
        Feature::Variance => &args.variance,
    };
    let layer = |f: Feature| exr.as_ref().and_then(|exr| feature_layer(exr, f));
    let has_layer = |f: Feature| layer(f).is_some();
    let device = hush_pipeline::device(args.device.as_deref())?;
    let (model, model_name, inference) = match &args.model {
        Some(path) => (Denoiser::load_on(path, &device)?, path.display().to_string(), Inference::PLAIN),
        None => {
            // The shipped model for the features at hand where one beats OIDN on the held-out scenes
            // (`cargo xtask train-default` measures it), else OIDN's official weights for them; both built in
            // (OIDN takes a normal only with an albedo).
            let has = |f: Feature| given(f).is_some() || has_layer(f);
            let features = match (has(Feature::Albedo), has(Feature::Normal)) {
                (true, true) => vec![Feature::Albedo, Feature::Normal],
                (true, false) => vec![Feature::Albedo],
                (false, _) => vec![],
            };
            let model = default_for(&InputFeatures { aux: features });
            eprintln!("model: {} (built in; --model to choose another)", model.name());
            (model.denoiser_on(&device)?, model.name(), model.inference())
        }
    };
    // The flags override the model's default setting.
    let poses = args.poses.map_or(inference.poses, usize::from);
    let restore_low_band = args.restore_low_band.map_or(inference.restore_low_band, |s| s.0);
    if poses > 1 {
        eprintln!(
            "denoising in {poses} poses{} (--poses 1 for one pass, {poses} times faster)",
            if restore_low_band.is_some() { ", the input's low band restored where they disagree" } else { "" }
        );
    }
    // The variance also serves --keep-exact and --blend-input, whatever the model takes.
    let wants_variance = args.keep_exact || args.blend_input.is_some() || restore_low_band.is_some();
    let unused = |f: &Feature| !(model.features().contains(f) || (*f == Feature::Variance && wants_variance));
    for f in Feature::ALL.into_iter().filter(|f| given(*f).is_some() && unused(f)) {
        eprintln!("warning: --{} is ignored: model {} takes {}", f.long_name(), model_name, model.info.features);
    }
    let mut aux: Vec<Image> = Vec::new();
    for &f in model.features() {
        let given = given(f);
        let image = match given {
            Some(path) => read_image(path)?,
            None if has_layer(f) => layer(f).expect("has_layer found it")?,
            None => bail!(
                "model {} needs --{} (its features are {}); {} has no '{}' layer either",
                model_name,
                f.long_name(),
                model.info.features,
                args.color.display(),
                layer_name(f)
            ),
        };
        aux.push(image);
    }
    for (name, image) in
        std::iter::once(("color", &color)).chain(model.features().iter().map(|f| f.long_name()).zip(&aux))
    {
        let bad = image.count_non_finite();
        if bad > 0 {
            eprintln!("warning: the {name} input holds {bad} NaN/Inf values; they are treated as 0");
        }
    }
    // The variance for keeping exact pixels and blending the input back: the model's own input where it takes
    // one, else --variance or the EXR's layer, where a variance that cannot be used is a warning (it serves
    // only those steps).
    let matches_color = |v: Image| -> Result<Image> {
        let (w, h, c) = (v.width, v.height, v.channels);
        if (w, h, c) != (color.width, color.height, 3) {
            bail!("it is {w}×{h}×{c}, the color {}×{}×3", color.width, color.height)
        }
        Ok(v)
    };
    let variance = match model.features().iter().position(|&f| f == Feature::Variance) {
        _ if !wants_variance => None,
        Some(i) => Some(aux[i].clone()),
        None => {
            let read = match (&args.variance, layer(Feature::Variance)) {
                (Some(path), _) => Some(read_image(path).with_context(|| format!("reading {}", path.display()))),
                (None, Some(image)) => {
                    Some(image.with_context(|| format!("the variance layer of {}", args.color.display())))
                }
                (None, None) => None,
            };
            match read.map(|r| r.and_then(matches_color)) {
                Some(Ok(v)) => Some(v),
                Some(Err(e)) => {
                    eprintln!("warning: no exact pixels kept, no input blended: the variance is unusable: {e:#}");
                    None
                }
                None => None,
            }
        }
    };
    let refs: Vec<&Image> = aux.iter().collect();
    let start = std::time::Instant::now();
    let outputs = model.denoise_poses(&color, &refs, poses)?;
    let (mut out, restored) = hush_pipeline::combine(&outputs, &color, variance.as_ref(), restore_low_band)?;
    match restored {
        Some(weight) => {
            eprintln!("restored the input's low band where the {poses} poses disagree: its mean weight {weight:.4}")
        }
        None if restore_low_band.is_some() && poses > 1 => {
            eprintln!(
                "warning: the input's low band was not restored: no usable variance for the color (give \
                 --variance, or a `hush render` EXR, which carries it; --restore-low-band off to silence this)"
            )
        }
        None => {}
    }
    if let (Some(tau), Some(v)) = (args.blend_input, &variance) {
        let weight = hush_pipeline::blend_input(&mut out, &color, v, tau)?;
        eprintln!("blended the input back by its standard error: its mean weight {weight:.4}");
    }
    let kept = match variance.as_ref().filter(|_| args.keep_exact) {
        Some(v) => Some(hush_pipeline::keep_exact(&mut out, &color, v)?),
        None => None,
    };
    eprintln!(
        "denoised {}×{} in {:.3} s → {}{}",
        color.width,
        color.height,
        start.elapsed().as_secs_f64(),
        args.out.display(),
        match kept {
            Some(k) => format!(" ({k} pixels whose every sample agreed kept as rendered)"),
            None => String::new(),
        }
    );
    if is_pfm(&args.out) {
        write_pfm(&args.out, &out)?
    } else {
        write_rgb(&args.out, &out)?
    }
    Ok(())
}
