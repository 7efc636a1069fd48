use anyhow::{Context, Result, bail};
use hush_dataset::{Image, Manifest, Split, load_view, write_png_preview};
use hush_eval::{Report, Row, compare, exposure_of, time_median};

use crate::cli::EvalArgs;
use crate::denoiser::{Denoiser, aux_of};

/// A method name for a model file: `<run folder>/<file stem>`.
fn method_name(path: &std::path::Path) -> String {
    let stem = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    match path.parent().and_then(|p| p.file_name()) {
        Some(dir) => format!("{}/{stem}", dir.to_string_lossy()),
        None => stem,
    }
}

pub fn run(args: EvalArgs) -> Result<()> {
    let manifest = Manifest::load(&args.dataset)?;
    let views: Vec<_> = manifest.split(Split::Test).cloned().collect();
    if views.is_empty() {
        bail!("{} has no test views: render the dataset with --test-views 1 or more", args.dataset.display());
    }
    let models: Vec<(String, Denoiser)> =
        args.models.iter().map(|p| Ok((method_name(p), Denoiser::load(p)?))).collect::<Result<_>>()?;
    let previews = args.out.join("previews");
    std::fs::create_dir_all(&previews).with_context(|| format!("creating {}", previews.display()))?;

    let mut report = Report::default();
    report.notes.push(format!("Dataset: {} ({} test views).", args.dataset.display(), views.len()));
    for (name, m) in &models {
        report.notes.push(format!(
            "Model {name}: {:?} width {} on features {}.",
            m.info.net.kind, m.info.net.width, m.info.features
        ));
    }
    report.notes.push(format!(
        "Machine: {} logical CPUs; denoise time is the median of {} warm runs on {}.",
        std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1),
        args.timing_runs.max(1),
        if cfg!(feature = "cuda") { "CUDA" } else { "the CPU" }
    ));

    for view in &views {
        let name = format!("{}_{}", view.scene, view.view);
        let spps: Vec<u32> =
            view.noisy.iter().map(|r| r.spp).filter(|s| args.spp.is_empty() || args.spp.contains(s)).collect();
        let mut reference_row = true;
        for spp in spps {
            let images = load_view(&args.dataset, view, spp)?;
            let exposure = exposure_of(&images.reference)?;
            let preview = |method: &str, image: &Image| -> Result<String> {
                let file = format!("{name}_{spp:06}_{}.png", method.replace('/', "-"));
                write_png_preview(previews.join(&file), image, exposure)?;
                Ok(format!("previews/{file}"))
            };
            if std::mem::take(&mut reference_row) {
                let mut row = Row::new(
                    &name,
                    "reference",
                    view.reference.spp,
                    &compare(&images.reference, &images.reference)?,
                    Some(view.reference.render_seconds),
                );
                row.preview = Some(preview("reference", &images.reference)?);
                report.rows.push(row);
            }
            let render_seconds = view.noisy_at(spp).map(|r| r.render_seconds);
            let mut row = Row::new(&name, "noisy", spp, &compare(&images.color, &images.reference)?, render_seconds);
            row.preview = Some(preview("noisy", &images.color)?);
            report.rows.push(row);
            for (method, model) in &models {
                let aux: Vec<&Image> = model.features().iter().map(|&f| aux_of(&images, f)).collect();
                let denoised = model.denoise(&images.color, &aux)?;
                let timing = time_median(args.timing_runs, 1, || model.denoise(&images.color, &aux));
                let mut row =
                    Row::new(&name, method, spp, &compare(&denoised, &images.reference)?, Some(timing.median));
                row.preview = Some(preview(method, &denoised)?);
                report.rows.push(row);
            }
        }
    }
    report.write(&args.out)?;
    eprintln!("report: {}", args.out.join(Report::MARKDOWN_FILE).display());
    Ok(())
}
