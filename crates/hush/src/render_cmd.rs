use std::time::Duration;

use anyhow::{Context, Result, bail};
use glam::Vec3;
use hush_dataset::{write_exr, write_png_preview};
use hush_scene::Scene;
use hush_trace::{GpuContext, KernelFeatures, RenderOutput, RenderSettings, Renderer};
use indicatif::{ProgressBar, ProgressStyle};

use crate::cli::{RenderArgs, ViewOverrides};
use crate::cpu::cpu_seconds;

/// Loads a scene and applies the command line's overrides.
pub fn load_scene(path: &std::path::Path, view: &ViewOverrides) -> Result<Scene> {
    let mut scene = Scene::load(path)?;
    for w in &scene.warnings {
        eprintln!("warning: {w}");
    }
    if let Some(w) = view.width {
        scene.film.width = w;
    }
    if let Some(h) = view.height {
        scene.film.height = h;
    }
    if scene.film.width == 0 || scene.film.height == 0 {
        bail!("--width and --height must be at least 1");
    }
    if let Some(f) = view.fov {
        scene.camera.fov_y_deg = f;
    }
    if let Some(o) = view.origin {
        scene.camera.origin = Vec3::from(o);
    }
    if let Some(t) = view.target {
        scene.camera.target = Vec3::from(t);
    }
    if let Some(u) = view.up {
        scene.camera.up = Vec3::from(u);
    }
    if let Some(d) = view.max_depth {
        if d == 0 {
            bail!("--max-depth must be at least 1 (1 = emitters seen directly)");
        }
        scene.max_depth = d;
    }
    scene.camera.validate().map_err(|m| anyhow::anyhow!("{}: {m}", path.display()))?;
    Ok(scene)
}

/// Opens the GPU and says which adapter it is, so a fallback is never silent.
pub fn open_gpu() -> Result<GpuContext> {
    let gpu = GpuContext::new()?;
    eprintln!("adapter: {}", gpu.describe());
    Ok(gpu)
}

/// Renders with a progress bar: samples per pixel done, M paths/s and the time left (to the
/// spp asked for, or to the end of `time_limit`, which then bounds the render as in
/// [`Renderer::render_within`]).
pub fn render_with_progress(
    renderer: &Renderer,
    scene: &Scene,
    settings: &RenderSettings,
    time_limit: Option<Duration>,
    label: &str,
) -> Result<RenderOutput> {
    // With a time limit the bar measures time (in milliseconds), so its ETA is the budget left.
    let (len, template) = match time_limit {
        None => (settings.spp as u64, "{prefix} [{bar:30}] {pos}/{len} spp {msg} eta {eta}"),
        Some(limit) => (limit.as_millis().max(1) as u64, "{prefix} [{bar:30}] {msg} eta {eta}"),
    };
    let bar = ProgressBar::new(len);
    bar.set_style(ProgressStyle::with_template(template).expect("valid template").progress_chars("=> "));
    bar.set_prefix(label.to_string());
    let pixels = scene.film.width as f64 * scene.film.height as f64;
    let start = std::time::Instant::now();
    let out = renderer.render_within(scene, settings, time_limit, &mut |done, _| {
        let elapsed = start.elapsed();
        let rate = pixels * done as f64 / elapsed.as_secs_f64().max(1e-9) / 1e6;
        match time_limit {
            None => {
                bar.set_message(format!("{rate:.2} M paths/s"));
                bar.set_position(done as u64);
            }
            Some(_) => {
                bar.set_message(format!("{done} spp {rate:.2} M paths/s"));
                bar.set_position((elapsed.as_millis() as u64).min(len));
            }
        }
    })?;
    bar.finish_and_clear();
    if out.discarded_samples > 0 {
        eprintln!("warning: {label}: {} non-finite path samples were discarded", out.discarded_samples);
    }
    Ok(out)
}

/// The mean Rec. 709 luminance of an image's finite pixels (0 for none).
fn mean_luminance(image: &hush_dataset::Image) -> f64 {
    let values: Vec<f64> =
        image.data.chunks_exact(3).map(|p| hush_dataset::luminance(p) as f64).filter(|l| l.is_finite()).collect();
    values.iter().sum::<f64>() / values.len().max(1) as f64
}

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
    let scene = load_scene(&args.scene, &args.view)?;
    let gpu = open_gpu()?;
    let renderer = Renderer::new(&gpu)?.with_generic_kernel(args.generic);
    let kernel = if args.generic { KernelFeatures::ALL } else { KernelFeatures::of(&scene) };
    eprintln!("scene: {} triangles; kernel: {kernel:?}", scene.triangle_count());
    let cpu0 = cpu_seconds();
    let out = render_with_progress(&renderer, &scene, &RenderSettings { spp, seed: args.seed }, time_limit, "render")?;
    let cpu = cpu_seconds() - cpu0;
    eprintln!("scene data written into the kernel: {}", out.literals);
    write_exr(
        &args.out,
        &[
            ("", &out.color),
            ("albedo", &out.albedo),
            ("diffuse", &out.diffuse),
            ("specular", &out.specular),
            ("normal", &out.normal),
        ],
    )
    .with_context(|| format!("writing {}", args.out.display()))?;
    if let Some(png) = &args.png {
        write_png_preview(png, &out.color, 1.0)?;
    }
    let paths = scene.film.width as f64 * scene.film.height as f64 * out.spp as f64;
    eprintln!(
        "{}×{} at {} spp ({} pass{}) in {:.2} s ({:.2} CPU-s): {:.3} M paths/s, {:.3} M paths per CPU-second → {}",
        scene.film.width,
        scene.film.height,
        out.spp,
        out.passes,
        if out.passes == 1 { "" } else { "es" },
        out.seconds,
        cpu,
        paths / out.seconds / 1e6,
        paths / cpu / 1e6,
        args.out.display()
    );
    if let Some(stats) = &args.stats {
        let json = serde_json::json!({
            "scene": args.scene,
            "width": scene.film.width,
            "height": scene.film.height,
            "spp": out.spp,
            "passes": out.passes,
            "time_limit_seconds": args.time_limit,
            "max_depth": scene.max_depth,
            "paths": paths,
            "wall_seconds": out.seconds,
            "cpu_seconds": cpu,
            "mpaths_per_second": paths / out.seconds / 1e6,
            "mpaths_per_cpu_second": paths / cpu / 1e6,
            "adapter": gpu.describe(),
            "non_finite_values": out.color.count_non_finite(),
            "discarded_samples": out.discarded_samples,
            "mean_luminance": mean_luminance(&out.color),
        });
        hush_dataset::write_atomic(stats, |tmp| std::fs::write(tmp, serde_json::to_string_pretty(&json)?))
            .with_context(|| format!("writing {}", stats.display()))?;
    }
    Ok(())
}
