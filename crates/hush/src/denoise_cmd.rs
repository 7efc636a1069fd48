//! `hush denoise`: one image through a trained model (or OIDN's weights), its features from the flags or
//! from the layers of a `hush render` EXR.

use anyhow::{Context, Result, bail};
use hush_dataset::{Image, read_exr, read_rgb, write_rgb};
use hush_net::{Feature, InputFeatures};
use hush_pipeline::Denoiser;
use hush_pipeline::official::official_for;

use crate::cli::DenoiseArgs;

/// The layer of a `hush render` EXR that holds a feature.
fn layer_name(f: Feature) -> &'static str {
    f.long_name()
}

pub fn run(args: DenoiseArgs) -> Result<()> {
    let exr = read_exr(&args.color)?;
    let given = |f: Feature| match f {
        Feature::Albedo => &args.albedo,
        Feature::Normal => &args.normal,
        Feature::Diffuse => &args.diffuse,
        Feature::Specular => &args.specular,
    };
    let has_layer = |f: Feature| exr.channels.keys().any(|k| k.starts_with(&format!("{}.", layer_name(f))));
    let (model, model_name) = match &args.model {
        Some(path) => (Denoiser::load(path)?, path.display().to_string()),
        None => {
            // Until a hush model beats OIDN's on held-out scenes (`cargo xtask train-default` measures it),
            // the default is OIDN's official weights for the features at hand, built in (OIDN takes a normal
            // only with an albedo).
            let has = |f: Feature| given(f).is_some() || has_layer(f);
            let features = match (has(Feature::Albedo), has(Feature::Normal)) {
                (true, true) => vec![Feature::Albedo, Feature::Normal],
                (true, false) => vec![Feature::Albedo],
                (false, _) => vec![],
            };
            let weights = official_for(&InputFeatures { aux: features });
            eprintln!("model: {} (built in; --model to choose another)", weights.method_name());
            (Denoiser::official(&weights)?, weights.method_name())
        }
    };
    let color = exr.layer("").with_context(|| format!("reading the color of {}", args.color.display()))?;
    for f in Feature::ALL.into_iter().filter(|f| given(*f).is_some() && !model.features().contains(f)) {
        eprintln!("warning: --{} is ignored: model {} takes {}", f.long_name(), model_name, model.info.features);
    }
    let mut aux: Vec<Image> = Vec::new();
    for &f in model.features() {
        let given = given(f);
        let image = match given {
            Some(path) => read_rgb(path)?,
            None if has_layer(f) => exr.layer(layer_name(f))?,
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
    let refs: Vec<&Image> = aux.iter().collect();
    let start = std::time::Instant::now();
    let out = model.denoise(&color, &refs)?;
    eprintln!(
        "denoised {}×{} in {:.3} s → {}",
        color.width,
        color.height,
        start.elapsed().as_secs_f64(),
        args.out.display()
    );
    write_rgb(&args.out, &out)?;
    Ok(())
}
