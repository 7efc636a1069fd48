//! `hush render`: one scene to a multi-layer EXR (beauty and the auxiliary features), with its statistics.

use std::time::Duration;

use anyhow::{Context, Result, bail};
use hush_dataset::{write_exr, write_png_preview};
use hush_pipeline::process::cpu_seconds;
use hush_pipeline::{RenderStats, load_scene};
use hush_trace::{KernelFeatures, RenderSettings, Renderer};

use crate::cli::RenderArgs;

pub fn run(args: RenderArgs) -> Result<()> {
    if args.spp == Some(0) {
        bail!("--spp must be at least 1");
    }
    let time_limit = match args.time_limit {
        None => None,
        Some(t) if t.is_finite() && t > 0.0 => Some(Duration::from_secs_f64(t)),
        Some(t) => bail!("--time-limit must be a positive number of seconds, not {t}"),
    };
    // Without --spp the time limit alone ends the render.
    let spp = args.spp.unwrap_or(u32::MAX);
    let scene = load_scene(&args.scene, &args.view.overrides())?;
    for w in &scene.warnings {
        eprintln!("warning: {w}");
    }
    let gpu = crate::open_gpu()?;
    let renderer = Renderer::new(&gpu)?.with_generic_kernel(args.generic);
    let kernel = if args.generic { KernelFeatures::ALL } else { KernelFeatures::of(&scene) };
    eprintln!("scene: {} triangles; kernel: {kernel:?}", scene.triangle_count());
    let settings = RenderSettings { spp, seed: args.seed, pixel_sampler: args.pixel_sampler };
    let warm_up_cpu = if args.warm_up {
        let cpu0 = cpu_seconds();
        renderer.render(&scene, &RenderSettings { spp: 1, ..settings }, &mut |_, _| {})?;
        Some(cpu_seconds() - cpu0)
    } else {
        None
    };
    let cpu0 = cpu_seconds();
    let out = crate::progress::render(&renderer, &scene, &settings, time_limit, "render")?;
    let cpu = cpu_seconds() - cpu0;
    if out.discarded_samples > 0 {
        eprintln!("warning: render: {} non-finite path samples were discarded", out.discarded_samples);
    }
    eprintln!("scene data written into the kernel: {}", out.literals);
    write_exr(
        &args.out,
        &[
            ("", &out.color),
            ("albedo", &out.albedo),
            ("diffuse", &out.diffuse),
            ("specular", &out.specular),
            ("normal", &out.normal),
            ("variance", &out.color_variance),
        ],
    )
    .with_context(|| format!("writing {}", args.out.display()))?;
    if let Some(png) = &args.png {
        write_png_preview(png, &out.color, 1.0)?;
    }
    let mut stats = RenderStats::new(&args.scene, &scene, &out, cpu, gpu.describe(), args.time_limit);
    stats.warm_up_cpu_seconds = warm_up_cpu;
    eprintln!(
        "{}×{} at {} spp ({} pass{}) in {:.2} s ({:.2} CPU-s): {:.3} M paths/s, {:.3} M paths per CPU-second → {}",
        stats.width,
        stats.height,
        stats.spp,
        stats.passes,
        if stats.passes == 1 { "" } else { "es" },
        stats.wall_seconds,
        stats.cpu_seconds,
        stats.mpaths_per_second,
        stats.mpaths_per_cpu_second,
        args.out.display()
    );
    if let Some(path) = &args.stats {
        // Through a JSON value, so the keys are sorted as in every other JSON file hush writes.
        let json = serde_json::to_string_pretty(&serde_json::to_value(&stats)?)?;
        hush_dataset::write_atomic(path, |tmp| std::fs::write(tmp, json))
            .with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
}
