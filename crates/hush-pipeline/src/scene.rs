//! Loading a scene with the camera and image overrides a user gives (`hush render --width ...`), and the
//! statistics of a render (`hush render --stats`).

use std::path::{Path, PathBuf};

use anyhow::{Result, anyhow, bail};
use glam::Vec3;
use hush_dataset::{Image, luminance};
use hush_scene::Scene;
use hush_trace::RenderOutput;
use serde::Serialize;

/// Camera and image settings that replace the scene file's. `None` keeps the file's value.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ViewOverrides {
    pub width: Option<u32>,
    pub height: Option<u32>,
    /// The vertical field of view in degrees.
    pub fov: Option<f32>,
    pub origin: Option<[f32; 3]>,
    pub target: Option<[f32; 3]>,
    pub up: Option<[f32; 3]>,
    /// Mitsuba's max_depth: 1 = emitters only, 2 = direct light, 8 = up to 7 bounces.
    pub max_depth: Option<u32>,
}

impl ViewOverrides {
    /// A square image of `size` pixels, or the file's size for `None`.
    pub fn square(size: Option<u32>) -> Self {
        ViewOverrides { width: size, height: size, ..Default::default() }
    }

    /// Applies the overrides to `scene` (loaded from `path`, which errors name).
    pub fn apply(&self, scene: &mut Scene, path: &Path) -> Result<()> {
        if let Some(w) = self.width {
            scene.film.width = w;
        }
        if let Some(h) = self.height {
            scene.film.height = h;
        }
        if scene.film.width == 0 || scene.film.height == 0 {
            bail!("--width and --height must be at least 1");
        }
        if let Some(f) = self.fov {
            scene.camera.fov_y_deg = f;
        }
        if let Some(o) = self.origin {
            scene.camera.origin = Vec3::from(o);
        }
        if let Some(t) = self.target {
            scene.camera.target = Vec3::from(t);
        }
        if let Some(u) = self.up {
            scene.camera.up = Vec3::from(u);
        }
        if let Some(d) = self.max_depth {
            if d == 0 {
                bail!("--max-depth must be at least 1 (1 = emitters seen directly)");
            }
            scene.max_depth = d;
        }
        scene.camera.validate().map_err(|m| anyhow!("{}: {m}", path.display()))
    }
}

/// Loads a scene file (Mitsuba XML, glTF, OBJ) and applies `overrides`. What the loader does not support is
/// in the scene's `warnings`, for the caller to show.
///
/// ```
/// use hush_pipeline::{ViewOverrides, load_scene};
///
/// let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data/scenes/cbox/scene.xml");
/// let overrides = ViewOverrides { width: Some(64), max_depth: Some(2), ..ViewOverrides::square(Some(32)) };
/// let scene = load_scene(&path, &overrides).unwrap();
/// assert_eq!((scene.film.width, scene.film.height, scene.max_depth), (64, 32, 2));
/// let err = load_scene(&path, &ViewOverrides { max_depth: Some(0), ..Default::default() }).unwrap_err();
/// assert!(err.to_string().contains("--max-depth"));
/// ```
pub fn load_scene(path: &Path, overrides: &ViewOverrides) -> Result<Scene> {
    let mut scene = Scene::load(path)?;
    overrides.apply(&mut scene, path)?;
    Ok(scene)
}

/// What `hush render --stats` records of a render.
#[derive(Clone, Debug, Serialize)]
pub struct RenderStats {
    pub scene: PathBuf,
    pub width: u32,
    pub height: u32,
    pub spp: u32,
    pub passes: u32,
    pub time_limit_seconds: Option<f64>,
    pub max_depth: u32,
    pub paths: f64,
    pub wall_seconds: f64,
    pub cpu_seconds: f64,
    pub mpaths_per_second: f64,
    pub mpaths_per_cpu_second: f64,
    pub adapter: String,
    pub non_finite_values: usize,
    pub discarded_samples: u64,
    pub mean_luminance: f64,
    /// With `hush render --warm-up`: the CPU-seconds of the untimed 1-spp render before the timed
    /// one, most of it compiling the kernel specialized to the scene (not in `cpu_seconds`).
    pub warm_up_cpu_seconds: Option<f64>,
}

impl RenderStats {
    /// The statistics of `out`, a render of `scene` (from `path`) that took `cpu_seconds` of this process on
    /// `adapter`, with the time limit it was given.
    pub fn new(
        path: &Path,
        scene: &Scene,
        out: &RenderOutput,
        cpu_seconds: f64,
        adapter: String,
        time_limit_seconds: Option<f64>,
    ) -> Self {
        let paths = scene.film.width as f64 * scene.film.height as f64 * out.spp as f64;
        RenderStats {
            scene: path.to_path_buf(),
            width: scene.film.width,
            height: scene.film.height,
            spp: out.spp,
            passes: out.passes,
            time_limit_seconds,
            max_depth: scene.max_depth,
            paths,
            wall_seconds: out.seconds,
            cpu_seconds,
            mpaths_per_second: paths / out.seconds / 1e6,
            mpaths_per_cpu_second: paths / cpu_seconds / 1e6,
            adapter,
            non_finite_values: out.color.count_non_finite(),
            discarded_samples: out.discarded_samples,
            mean_luminance: mean_luminance(&out.color),
            warm_up_cpu_seconds: None,
        }
    }
}

/// The mean Rec. 709 luminance of an image's finite pixels (0 for none).
pub fn mean_luminance(image: &Image) -> f64 {
    let values: Vec<f64> = image.data.chunks_exact(3).map(|p| luminance(p) as f64).filter(|l| l.is_finite()).collect();
    values.iter().sum::<f64>() / values.len().max(1) as f64
}
