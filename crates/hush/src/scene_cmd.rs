//! `hush scene generate`: a seeded procedural scene (hush-pipeline's `procedural`), written atomically with
//! its assets and probed on the GPU, so that no scene whose camera sees nothing lit is ever written.
//! `hush scene check`: a scene file loaded as `hush render` loads it, without a GPU: its warnings, what it
//! holds, or the error that names what is wrong.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use clap::{Args, Subcommand};
use hush_dataset::write_atomic;
use hush_pipeline::procedural::{generate_into, summary_json};
use hush_scene::PixelFilter;
use hush_scene::procedural::{GeneratorOptions, LightMaterial, Style};
use hush_trace::Renderer;

use crate::cli::GeneratorArgs;

#[derive(Args, Debug)]
pub struct SceneArgs {
    #[command(subcommand)]
    pub action: SceneAction,
}

#[derive(Subcommand, Debug)]
pub enum SceneAction {
    /// Write a seeded procedural scene (Mitsuba 3 XML and its assets): a room with openings, furniture,
    /// random materials and lights. The same seed gives the same scene.
    Generate(GenerateArgs),
    /// Load a scene file (Mitsuba XML, OBJ, glTF) as `hush render` does, without a GPU: print its warnings
    /// and what it holds, or fail with the error that names what is wrong.
    Check(CheckArgs),
}

#[derive(Args, Debug)]
pub struct CheckArgs {
    /// Scene file.
    pub scene: PathBuf,
}

#[derive(Args, Debug)]
pub struct GenerateArgs {
    /// Seed of the scene.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Scene file to write; its assets (textures, an environment map) go into the same folder.
    #[arg(long)]
    pub out: PathBuf,
    #[command(flatten)]
    pub generator: GeneratorArgs,
    /// Also write what the scene holds (style, materials, lights, probe) as JSON.
    #[arg(long)]
    pub summary: Option<PathBuf>,
    /// Write the scene without the GPU probe that rejects a camera seeing nothing lit.
    #[arg(long)]
    pub no_probe: bool,
    /// The scene's style: standard, dark, glass, spotlit (rooms, otherwise drawn from the seed) or open
    /// (objects on a ground plane under a sky).
    #[arg(long, value_parser = parse_style)]
    pub style: Option<Style>,
    /// The film's pixel filter: box, tent (radius 1) or gaussian (σ 0.5), as Mitsuba's.
    #[arg(long, default_value = "box", value_parser = parse_filter)]
    pub filter: PixelFilter,
    /// What a room's ceiling panels and lamps are made of: black (their edge shows in the albedo) or
    /// ceiling (the ceiling's material, as the Cornell box's light: only the colour shows their edge).
    /// The room is otherwise the same.
    #[arg(long, default_value = "black", value_parser = parse_light_material)]
    pub light_material: LightMaterial,
}

fn parse_light_material(name: &str) -> Result<LightMaterial, String> {
    LightMaterial::parse(name).ok_or_else(|| {
        let names: Vec<_> = LightMaterial::ALL.iter().map(|m| m.name()).collect();
        format!("unknown light material '{name}': use {}", names.join(", "))
    })
}

fn parse_filter(name: &str) -> Result<PixelFilter, String> {
    match name {
        "box" => Ok(PixelFilter::Box),
        "tent" => Ok(PixelFilter::Tent { radius: 1.0 }),
        "gaussian" => Ok(PixelFilter::MITSUBA_DEFAULT),
        other => Err(format!("unknown pixel filter '{other}': use box, tent or gaussian")),
    }
}

fn parse_style(name: &str) -> Result<Style, String> {
    Style::parse(name).ok_or_else(|| {
        let names: Vec<_> = Style::ALL.iter().map(|s| s.name()).collect();
        format!("unknown style '{name}': use {}", names.join(", "))
    })
}

pub fn run(args: SceneArgs) -> Result<()> {
    match args.action {
        SceneAction::Generate(a) => generate(a),
        SceneAction::Check(a) => check(a),
    }
}

fn check(args: CheckArgs) -> Result<()> {
    let scene = hush_scene::Scene::load(&args.scene)?;
    for w in &scene.warnings {
        eprintln!("warning: {w}");
    }
    let lights = scene.meshes.iter().filter(|m| m.emission.is_some()).count();
    println!(
        "{}: {} shapes, {} triangles, {} textures, {lights} emitting shapes{}, {}×{} film, max_depth {}, {} warnings",
        args.scene.display(),
        scene.meshes.len(),
        scene.triangle_count(),
        scene.textures.len(),
        if scene.environment.is_some() { " and an environment" } else { "" },
        scene.film.width,
        scene.film.height,
        scene.max_depth,
        scene.warnings.len()
    );
    Ok(())
}

fn generate(args: GenerateArgs) -> Result<()> {
    if args.out.extension().is_none_or(|e| !e.eq_ignore_ascii_case("xml")) {
        bail!("--out {}: the scene is Mitsuba XML; name the file *.xml", args.out.display());
    }
    let options = GeneratorOptions {
        style: args.style,
        filter: args.filter,
        light_material: args.light_material,
        ..args.generator.options(256, 256)
    };
    let gpu = if args.no_probe { None } else { Some(crate::open_gpu()?) };
    let renderer = gpu.as_ref().map(Renderer::new).transpose()?;
    let written = generate_into(&args.out, args.seed, 0, &options, renderer.as_ref())?;
    let s = summary_json(&written, args.seed, 0, &options);
    eprintln!(
        "scene: seed {}, style {}, {} shapes, materials {}, lights {}{} → {}",
        args.seed,
        written.scene.style,
        written.scene.shapes.len(),
        s["materials"],
        s["lights"],
        written.lit_fraction.map(|f| format!(", probe {:.0} % lit", f * 100.0)).unwrap_or_default(),
        args.out.display()
    );
    if let Some(path) = &args.summary {
        write_atomic(path, |tmp| std::fs::write(tmp, serde_json::to_string_pretty(&s)?))
            .with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
}
