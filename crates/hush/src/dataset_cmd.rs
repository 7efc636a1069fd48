use std::path::Path;

use anyhow::{Context, Result, bail};
use glam::{Quat, Vec3};
use hush_dataset::{AuxKind, AuxRecord, CameraRecord, Layout, Manifest, RenderRecord, Split, ViewRecord, write_rgb};
use hush_scene::{Camera, Scene};
use hush_trace::{RenderSettings, Renderer};

use crate::cli::{DatasetArgs, ViewOverrides};
use crate::render_cmd::{load_scene, open_gpu, render_with_progress};

/// SplitMix64: a tiny, well-mixed generator for seeds and view jitter.
pub struct SplitMix(pub u64);

impl SplitMix {
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in [lo, hi).
    pub fn uniform(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * ((self.next_u64() >> 40) as f32 / (1u64 << 24) as f32)
    }
}

/// A seed for one render, derived from the dataset seed and what is rendered, so that every
/// image (and the reference in particular) is statistically independent of every other.
fn render_seed(seed: u64, scene: &str, view: u32, what: &str) -> u64 {
    let mut h = SplitMix(seed);
    let mut acc = h.next_u64();
    for b in scene.bytes().chain([0xff]).chain(what.bytes()) {
        acc = SplitMix(acc ^ b as u64).next_u64();
    }
    SplitMix(acc ^ view as u64).next_u64()
}

/// View 0 is the scene's camera; the others orbit its target by up to ±20° of yaw and ±8° of
/// pitch, move 10 % closer or farther, shift the target by up to 3 % of the scene's size and
/// scale the field of view by ±10 %.
fn jitter_camera(base: &Camera, scene: &Scene, seed: u64, view: u32) -> Camera {
    if view == 0 {
        return *base;
    }
    let mut rng = SplitMix(render_seed(seed, "view-jitter", view, ""));
    let (forward, right, up) = base.basis();
    let yaw = Quat::from_axis_angle(up, rng.uniform(-20.0, 20.0).to_radians());
    let pitch = Quat::from_axis_angle(right, rng.uniform(-8.0, 8.0).to_radians());
    let (lo, hi) = scene.bounds();
    let size = if lo.is_finite() && hi.is_finite() { (hi - lo).length() } else { 1.0 };
    let shift = Vec3::new(rng.uniform(-1.0, 1.0), rng.uniform(-1.0, 1.0), rng.uniform(-1.0, 1.0)) * 0.03 * size;
    let target = base.target + shift;
    let dist = (base.origin - base.target).length() * rng.uniform(0.9, 1.1);
    let dir = (yaw * pitch * forward).normalize();
    Camera {
        origin: target - dir * dist,
        target,
        up: base.up,
        fov_y_deg: (base.fov_y_deg * rng.uniform(0.9, 1.1)).min(170.0),
    }
}

/// `<parent folder>` of a scene file, made into a valid dataset name.
fn scene_name(path: &Path) -> String {
    let stem = match path.file_stem().and_then(|s| s.to_str()) {
        Some("scene") | None => path.parent().and_then(|p| p.file_name()).and_then(|s| s.to_str()).unwrap_or("scene"),
        Some(s) => s,
    };
    let name: String = stem.chars().map(|c| if c.is_ascii_alphanumeric() || c == '-' { c } else { '-' }).collect();
    if name.is_empty() { "scene".into() } else { name }
}

fn camera_record(scene: &Scene) -> CameraRecord {
    let c = &scene.camera;
    CameraRecord {
        origin: c.origin.to_array(),
        target: c.target.to_array(),
        up: c.up.to_array(),
        fov_y_deg: c.fov_y_deg,
        width: scene.film.width,
        height: scene.film.height,
    }
}

pub fn run(args: DatasetArgs) -> Result<()> {
    if args.spp.is_empty() || args.spp.contains(&0) || args.ref_spp == 0 || args.aux_spp == 0 {
        bail!("every spp (--spp, --ref-spp, --aux-spp) must be at least 1");
    }
    if args.views == 0 || args.test_views > args.views {
        bail!("--views must be at least 1 and --test-views at most --views");
    }
    std::fs::create_dir_all(&args.out).with_context(|| format!("creating {}", args.out.display()))?;
    let layout = Layout::new(&args.out);
    let mut manifest = Manifest::load_or_default(&args.out)?;
    let gpu = open_gpu()?;
    let renderer = Renderer::new(&gpu);
    let overrides = ViewOverrides { width: args.size, height: args.size, ..Default::default() };
    let mut spps = args.spp.clone();
    spps.sort_unstable();
    spps.dedup();

    for scene_path in &args.scenes {
        let base = load_scene(scene_path, &overrides)?;
        let name = scene_name(scene_path);
        for v in 0..args.views {
            let view = format!("v{v:03}");
            let mut scene = base.clone();
            scene.camera = jitter_camera(&base.camera, &base, args.seed, v);
            let camera = camera_record(&scene);
            let split = if v >= args.views - args.test_views { Split::Test } else { Split::Train };
            // A view already in the manifest with the same camera keeps its finished images.
            let previous = manifest.get(&name, &view).filter(|r| r.camera == camera).cloned();
            let label = format!("{name} {view}");

            let mut noisy = Vec::new();
            for &spp in &spps {
                let file = Layout::noisy_name(&name, &view, spp);
                if let Some(r) =
                    previous.as_ref().and_then(|p| p.noisy_at(spp)).filter(|_| layout.path(&file).is_file())
                {
                    noisy.push(r.clone());
                    continue;
                }
                let seed = render_seed(args.seed, &name, v, &format!("noisy-{spp}"));
                let out = render_with_progress(
                    &renderer,
                    &scene,
                    &RenderSettings { spp, seed },
                    &format!("{label} {spp} spp"),
                )?;
                write_rgb(layout.path(&file), &out.color)?;
                noisy.push(RenderRecord { spp, seed, file, render_seconds: out.seconds });
            }

            let aux_files: Vec<String> = AuxKind::ALL.iter().map(|&k| Layout::aux_name(&name, &view, k)).collect();
            let aux = match previous.as_ref().map(|p| p.aux.clone()) {
                Some(a) if a.spp == args.aux_spp && aux_files.iter().all(|f| layout.path(f).is_file()) => a,
                _ => {
                    // Features come from the first hit only, so a depth-1 render gives them at a
                    // fraction of a full path's cost.
                    let mut first_hit = scene.clone();
                    first_hit.max_depth = 1;
                    let seed = render_seed(args.seed, &name, v, "aux");
                    let out = render_with_progress(
                        &renderer,
                        &first_hit,
                        &RenderSettings { spp: args.aux_spp, seed },
                        &format!("{label} features"),
                    )?;
                    for (kind, file) in AuxKind::ALL.iter().zip(&aux_files) {
                        let image = match kind {
                            AuxKind::Albedo => &out.albedo,
                            AuxKind::Normal => &out.normal,
                            AuxKind::Diffuse => &out.diffuse,
                            AuxKind::Specular => &out.specular,
                        };
                        write_rgb(layout.path(file), image)?;
                    }
                    AuxRecord {
                        spp: args.aux_spp,
                        seed,
                        render_seconds: out.seconds,
                        albedo: aux_files[0].clone(),
                        normal: aux_files[1].clone(),
                        diffuse: aux_files[2].clone(),
                        specular: aux_files[3].clone(),
                    }
                }
            };

            let ref_file = Layout::reference_name(&name, &view);
            let reference = match previous.as_ref().map(|p| p.reference.clone()) {
                Some(r) if r.spp == args.ref_spp && layout.path(&ref_file).is_file() => r,
                _ => {
                    let seed = render_seed(args.seed, &name, v, "reference");
                    let out = render_with_progress(
                        &renderer,
                        &scene,
                        &RenderSettings { spp: args.ref_spp, seed },
                        &format!("{label} reference"),
                    )?;
                    write_rgb(layout.path(&ref_file), &out.color)?;
                    RenderRecord { spp: args.ref_spp, seed, file: ref_file, render_seconds: out.seconds }
                }
            };

            manifest.upsert(ViewRecord {
                scene: name.clone(),
                view: view.clone(),
                split,
                camera,
                noisy,
                reference,
                aux,
            })?;
            // Saved after every view: a killed run loses at most the view in progress.
            manifest.save(&args.out)?;
            eprintln!("{label}: done ({split:?})");
        }
    }
    eprintln!("dataset: {} views in {}", manifest.views.len(), layout.manifest_path().display());
    Ok(())
}
