//! `manifest.json`: how every image of a dataset was rendered, and how a dataset rendered in shards merges.
//!
//! A run of `hush dataset` owns exactly one manifest file and rewrites it (atomically) after every finished
//! image: `manifest.json` when it renders everything, `manifest.shard-<i>-of-<n>.json` when it renders shard
//! `i` of `n`. Views still being rendered are kept under `pending`, so a killed run loses nothing it finished.
//! [`Manifest::load`] reads `manifest.json` and every shard part beside it and merges them (a part's record
//! wins over `manifest.json`'s for the same view), so readers never need an explicit merge step.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::{Error, Layout, Result, write_atomic};

/// `Train` or `Test`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Split {
    Train,
    Test,
}

/// The pinhole camera a view was rendered with.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CameraRecord {
    pub origin: [f32; 3],
    pub target: [f32; 3],
    pub up: [f32; 3],
    pub fov_y_deg: f32,
    pub width: u32,
    pub height: u32,
}

/// One rendered image.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RenderRecord {
    pub spp: u32,
    pub seed: u64,
    /// File name relative to the dataset root.
    pub file: String,
    /// Seconds spent tracing this image (the one-time pipeline creation is not included).
    pub render_seconds: f64,
    /// The render's own auxiliary images, accumulated over its samples (what a user denoising this render
    /// has, and what OIDN's default weights expect). `None` in datasets from before they were stored.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub aux: Option<AuxFiles>,
    /// The estimated variance of each beauty pixel's value (its samples' variance / spp, per channel):
    /// `<scene>_<view>_<spp>.var.exr`. `None` for renders from before it was stored, which are kept.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub variance: Option<String>,
    /// Where its pixels' samples lay: `stratified`, or `None` for independent positions (the default, and
    /// every render from before the sampler was recorded). A resume renders again what differs from the
    /// run's sampler.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pixel_sampler: Option<String>,
}

/// The four auxiliary images of one render.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct AuxFiles {
    pub albedo: String,
    pub normal: String,
    pub diffuse: String,
    pub specular: String,
}

impl AuxFiles {
    /// The files `name` gives each feature.
    pub fn from_fn(name: impl Fn(crate::AuxKind) -> String) -> AuxFiles {
        use crate::AuxKind::*;
        AuxFiles { albedo: name(Albedo), normal: name(Normal), diffuse: name(Diffuse), specular: name(Specular) }
    }

    /// The file of one feature.
    pub fn file(&self, kind: crate::AuxKind) -> &str {
        match kind {
            crate::AuxKind::Albedo => &self.albedo,
            crate::AuxKind::Normal => &self.normal,
            crate::AuxKind::Diffuse => &self.diffuse,
            crate::AuxKind::Specular => &self.specular,
        }
    }
}

/// The clean auxiliary images of a view, rendered together.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct AuxRecord {
    pub spp: u32,
    pub seed: u64,
    pub render_seconds: f64,
    /// The path depth they were rendered at: the scene's, so that they follow mirrors and glass to the
    /// surface seen through them, as each noisy render's own features do. Absent in datasets whose clean
    /// features were rendered at depth 1 (where mirrors and glass had none); a resume renders those again.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_depth: Option<u32>,
    #[serde(flatten)]
    pub files: AuxFiles,
    /// Where its pixels' samples lay: `stratified`, or `None` for independent positions (the default, and
    /// every render from before the sampler was recorded). A resume renders again what differs from the
    /// run's sampler.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pixel_sampler: Option<String>,
}

impl AuxRecord {
    /// The file of one feature.
    pub fn file(&self, kind: crate::AuxKind) -> &str {
        self.files.file(kind)
    }
}

/// What the firefly filter did to a reference (see [`crate::despeckle`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FireflyRecord {
    /// A pixel brighter than `factor` × the brightest of its 8 neighbours was clamped; 0 = filter off.
    pub factor: f32,
    pub clamped_pixels: usize,
    /// Fraction of the image's total luminance the clamp removed.
    pub energy_removed: f64,
}

/// The reference's error, measured against an independent render at a higher spp.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ReferenceCheck {
    pub spp: u32,
    pub seed: u64,
    pub render_seconds: f64,
    /// Mean of `(ref − check)² / (check² + 0.01)` over all samples (hush-eval's relMSE, linear HDR).
    pub rel_mse: f64,
}

/// The reference: rendered at `supersample`× the width and height with `spp` samples per (sub)pixel,
/// firefly-filtered at that resolution, then box-downsampled. A film whose pixel filter is not a box
/// is rendered at 1× (`supersample` 1) with the same paths per pixel: downsampling would narrow its filter.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ReferenceRecord {
    /// Samples per subpixel; every final pixel averages `spp × supersample²` paths.
    pub spp: u32,
    pub seed: u64,
    pub file: String,
    pub render_seconds: f64,
    pub supersample: u32,
    pub firefly: FireflyRecord,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub check: Option<ReferenceCheck>,
    /// Where its pixels' samples lay: `stratified`, or `None` for independent positions (the default, and
    /// every render from before the sampler was recorded). A resume renders again what differs from the
    /// run's sampler.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pixel_sampler: Option<String>,
}

/// How a view's camera was chosen.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ViewGeneration {
    /// `scene` (the scene file's own camera) or `generated`.
    pub kind: String,
    /// The seed candidate cameras are drawn from (candidate `a` uses `seed + a`).
    pub seed: u64,
    /// The candidate that was kept (0-based); earlier ones were rejected by the probe.
    pub attempt: u32,
    /// The probe render that accepted it (generated views only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub probe: Option<ProbeRecord>,
}

/// A cheap render that decides whether a generated view sees enough lit surface.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ProbeRecord {
    pub width: u32,
    pub height: u32,
    pub spp: u32,
    /// Fraction of probe pixels with non-zero radiance.
    pub lit_fraction: f64,
    /// Whether it passed; a view none of whose candidates passed keeps the best one.
    pub accepted: bool,
}

/// Everything stored for one finished camera view of one scene.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ViewRecord {
    pub scene: String,
    pub view: String,
    pub split: Split,
    pub camera: CameraRecord,
    pub generation: ViewGeneration,
    /// Noisy renders, one per spp, sorted by spp.
    pub noisy: Vec<RenderRecord>,
    pub reference: ReferenceRecord,
    pub aux: AuxRecord,
    /// More renders of the same ladder with other seeds (`hush dataset --test-repeats`, test views only):
    /// `repeats[k - 1]` is the ladder of repeat `k`, its files under `repeats/`. An evaluation scores each
    /// spp by the mean over the noisy render and its repeats. Empty in every dataset without them.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub repeats: Vec<Vec<RenderRecord>>,
}

/// A view whose images are being rendered: what is finished so far.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PendingView {
    pub scene: String,
    pub view: String,
    pub split: Split,
    pub camera: CameraRecord,
    pub generation: ViewGeneration,
    pub noisy: Vec<RenderRecord>,
    pub reference: Option<ReferenceRecord>,
    pub aux: Option<AuxRecord>,
    /// [`ViewRecord::repeats`] finished so far.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub repeats: Vec<Vec<RenderRecord>>,
}

impl PendingView {
    /// The finished view, once the reference and the features are there.
    pub fn complete(&self) -> Option<ViewRecord> {
        Some(ViewRecord {
            scene: self.scene.clone(),
            view: self.view.clone(),
            split: self.split,
            camera: self.camera.clone(),
            generation: self.generation.clone(),
            noisy: self.noisy.clone(),
            reference: self.reference.clone()?,
            aux: self.aux.clone()?,
            repeats: self.repeats.clone(),
        })
    }
}

impl From<ViewRecord> for PendingView {
    fn from(v: ViewRecord) -> Self {
        PendingView {
            scene: v.scene,
            view: v.view,
            split: v.split,
            camera: v.camera,
            generation: v.generation,
            noisy: v.noisy,
            reference: Some(v.reference),
            aux: Some(v.aux),
            repeats: v.repeats,
        }
    }
}

impl ViewRecord {
    /// The noisy render at `spp`, if stored.
    pub fn noisy_at(&self, spp: u32) -> Option<&RenderRecord> {
        self.noisy.iter().find(|r| r.spp == spp)
    }

    /// Every render at `spp`: the noisy render first, then its repeats (`--test-repeats`) that have one.
    pub fn renders_at(&self, spp: u32) -> Vec<&RenderRecord> {
        self.noisy_at(spp)
            .into_iter()
            .chain(self.repeats.iter().filter_map(|ladder| ladder.iter().find(|r| r.spp == spp)))
            .collect()
    }

    /// Checks the names and that no spp appears twice in the ladder or in one of its repeats.
    pub fn validate(&self) -> Result<()> {
        validate_view(&self.scene, &self.view, &self.noisy)?;
        self.repeats.iter().try_for_each(|ladder| validate_view(&self.scene, &self.view, ladder))
    }
}

fn validate_view(scene: &str, view: &str, noisy: &[RenderRecord]) -> Result<()> {
    Layout::check_name("scene", scene)?;
    Layout::check_name("view", view)?;
    let mut spps: Vec<u32> = noisy.iter().map(|r| r.spp).collect();
    spps.sort_unstable();
    if let Some(w) = spps.windows(2).find(|w| w[0] == w[1]) {
        return Err(Error::Dataset(format!("view {scene}_{view} lists two noisy renders at {} spp", w[0])));
    }
    Ok(())
}

/// A scene of the job and the split its views belong to.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SceneEntry {
    pub name: String,
    /// The scene file as given on the command line (or found in a folder).
    pub path: String,
    /// `None` when the split is per view (a dataset of one scene: its last views test).
    pub split: Option<Split>,
    /// Triangles after loading.
    pub triangles: usize,
}

/// A scene file that could not be loaded; the job went on without it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SkippedScene {
    pub path: String,
    pub reason: String,
}

/// The settings of the run that wrote a manifest: what a complete dataset holds.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DatasetConfig {
    pub seed: u64,
    /// Views per scene: view `v000` is the scene's own camera, the others are generated.
    pub views: u32,
    /// The spp ladder of the noisy renders.
    pub spp: Vec<u32>,
    pub aux_spp: u32,
    pub ref_spp: u32,
    /// The test split's references' spp, where it differs from `ref_spp`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub test_ref_spp: Option<u32>,
    pub ref_supersample: u32,
    pub firefly_factor: f32,
    /// Samples per pixel of the independent render each reference is checked against; 0 = no check.
    pub ref_check_spp: u32,
    /// Square image size, if it overrides the scene files.
    pub size: Option<u32>,
    pub scenes: Vec<SceneEntry>,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub skipped: Vec<SkippedScene>,
    /// The procedural scenes the run generated (`--procedural N`), if any.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub procedural: Option<ProceduralRecord>,
    /// The pixel sampler of the run's renders (`stratified`); `None`: independent positions.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pixel_sampler: Option<String>,
    /// Renders of each test view's ladder, the noisy one included (`--test-repeats`); `None`: 1.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub test_repeats: Option<u32>,
}

/// Procedural scenes generated for a dataset: enough to generate the same scenes again.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ProceduralRecord {
    pub count: u32,
    pub seed: u64,
    /// hush-scene's generator version: the same seed gives the same scene only under the same version.
    pub generator_version: u32,
    /// The generator's features (`default`, `all` or a list).
    pub features: String,
    pub scenes: Vec<ProceduralScene>,
}

/// One generated scene.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ProceduralScene {
    pub index: u64,
    /// The scene file, relative to the dataset root.
    pub path: String,
    /// The generator's seed for the attempt kept (derived from the run's seed, the index and the attempt).
    pub scene_seed: u64,
    /// Attempts before it were rejected by the probe (their camera saw too little light).
    pub attempt: u32,
    pub style: String,
    /// Fraction of the probe render's pixels that received light.
    pub probe_lit_fraction: Option<f64>,
}

/// A manifest: every finished view, views in progress and the settings that produced them.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    pub format_version: u32,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub config: Option<DatasetConfig>,
    pub views: Vec<ViewRecord>,
    /// Views with some images finished (written after every image, so a killed run can resume).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub pending: Vec<PendingView>,
}

impl Default for Manifest {
    fn default() -> Self {
        Manifest { format_version: Self::FORMAT_VERSION, config: None, views: Vec::new(), pending: Vec::new() }
    }
}

/// The largest manifest hush reads: 256 MiB (a million views), or `HUSH_MAX_MANIFEST_BYTES` (bytes).
pub fn max_manifest_bytes() -> hush_io::Limit {
    hush_io::Limit::from_env("HUSH_MAX_MANIFEST_BYTES", 256 << 20)
}

impl Manifest {
    pub const FORMAT_VERSION: u32 = 2;
    pub const FILE_NAME: &'static str = "manifest.json";

    /// Reads `<root>/manifest.json` and every shard part `<root>/manifest.shard-*.json` and merges them:
    /// views are keyed by scene and view, a shard part's record replaces `manifest.json`'s (later parts
    /// replace earlier ones), and a pending view is dropped where a finished one exists. The config is
    /// `manifest.json`'s, else the first part's. Fails if there is neither file, or if one is malformed or
    /// of another format version.
    pub fn load(root: impl AsRef<Path>) -> Result<Self> {
        let layout = Layout::new(root.as_ref());
        let mut files = Vec::new();
        if layout.manifest_path().exists() {
            files.push(layout.manifest_path());
        }
        files.extend(layout.shard_manifest_paths()?);
        if files.is_empty() {
            return Err(Error::file(
                layout.manifest_path(),
                "read the dataset manifest (is this a dataset root? render one with `hush dataset`)",
                std::io::Error::from(std::io::ErrorKind::NotFound),
            ));
        }
        let parts = files.iter().map(|f| Self::load_file(f)).collect::<Result<Vec<_>>>()?;
        Ok(Self::merge(parts))
    }

    /// Like [`Manifest::load`], but an empty manifest if there is no manifest file yet.
    pub fn load_or_default(root: impl AsRef<Path>) -> Result<Self> {
        let layout = Layout::new(root.as_ref());
        if layout.manifest_path().exists() || !layout.shard_manifest_paths()?.is_empty() {
            Self::load(root)
        } else {
            Ok(Self::default())
        }
    }

    /// Reads one manifest file (no merging).
    pub fn load_file(path: &Path) -> Result<Self> {
        let text = hush_io::read_text_limited(path, max_manifest_bytes(), "dataset manifest")
            .map_err(|e| Error::file(path, "read the dataset manifest", e))?;
        let version = serde_json::from_str::<serde_json::Value>(&text)
            .ok()
            .and_then(|v| v.get("format_version").and_then(|n| n.as_u64()));
        if let Some(v) = version.filter(|&v| v != u64::from(Self::FORMAT_VERSION)) {
            return Err(Error::Dataset(format!(
                "{}: format_version {v} but this build reads {}; re-create the dataset with this build \
                 (`hush dataset ... --out` into a new folder)",
                path.display(),
                Self::FORMAT_VERSION
            )));
        }
        let manifest: Manifest = serde_json::from_str(&text).map_err(|source| Error::Json {
            path: path.to_path_buf(),
            action: "parsing",
            source,
        })?;
        for v in &manifest.views {
            v.validate().map_err(|e| Error::Dataset(format!("{}: {e}", path.display())))?;
        }
        for v in &manifest.pending {
            validate_view(&v.scene, &v.view, &v.noisy)
                .map_err(|e| Error::Dataset(format!("{}: {e}", path.display())))?;
        }
        Ok(manifest)
    }

    /// Merges manifests in order: later records replace earlier ones for the same scene and view.
    pub fn merge(parts: impl IntoIterator<Item = Manifest>) -> Manifest {
        let mut config = None;
        let mut views = BTreeMap::new();
        let mut pending = BTreeMap::new();
        for part in parts {
            if config.is_none() {
                config = part.config;
            }
            for v in part.views {
                pending.remove(&(v.scene.clone(), v.view.clone()));
                views.insert((v.scene.clone(), v.view.clone()), v);
            }
            for p in part.pending {
                let key = (p.scene.clone(), p.view.clone());
                if !views.contains_key(&key) {
                    pending.insert(key, p);
                }
            }
        }
        Manifest {
            format_version: Self::FORMAT_VERSION,
            config,
            views: views.into_values().collect(),
            pending: pending.into_values().collect(),
        }
    }

    /// Writes `<root>/manifest.json` atomically (see [`Manifest::save_file`]).
    pub fn save(&self, root: impl AsRef<Path>) -> Result<()> {
        self.save_file(&Layout::new(root.as_ref()).manifest_path())
    }

    /// Writes `path` atomically, pretty-printed, views sorted by scene and view.
    pub fn save_file(&self, path: &Path) -> Result<()> {
        let mut sorted = self.clone();
        sorted.views.sort_by(|a, b| (&a.scene, &a.view).cmp(&(&b.scene, &b.view)));
        sorted.pending.sort_by(|a, b| (&a.scene, &a.view).cmp(&(&b.scene, &b.view)));
        let mut text = serde_json::to_string_pretty(&sorted).map_err(|source| Error::Json {
            path: path.to_path_buf(),
            action: "writing",
            source,
        })?;
        text.push('\n');
        write_atomic(path, |tmp| std::fs::write(tmp, &text).map_err(|e| Error::file(path, "write", e)))
    }

    /// Inserts a finished `view`, replacing the record with the same scene and view (and dropping it from
    /// `pending`); returns the replaced one.
    pub fn upsert(&mut self, mut view: ViewRecord) -> Result<Option<ViewRecord>> {
        view.validate()?;
        view.noisy.sort_by_key(|r| r.spp);
        for ladder in &mut view.repeats {
            ladder.sort_by_key(|r| r.spp);
        }
        self.pending.retain(|p| !(p.scene == view.scene && p.view == view.view));
        match self.views.iter_mut().find(|v| v.scene == view.scene && v.view == view.view) {
            Some(old) => Ok(Some(std::mem::replace(old, view))),
            None => {
                self.views.push(view);
                Ok(None)
            }
        }
    }

    /// Records progress on a view: a finished view moves to `views`, an unfinished one to `pending`.
    pub fn upsert_progress(&mut self, mut progress: PendingView) -> Result<()> {
        validate_view(&progress.scene, &progress.view, &progress.noisy)?;
        progress.noisy.sort_by_key(|r| r.spp);
        for ladder in &mut progress.repeats {
            validate_view(&progress.scene, &progress.view, ladder)?;
            ladder.sort_by_key(|r| r.spp);
        }
        if let Some(done) = progress.complete() {
            self.upsert(done)?;
            return Ok(());
        }
        self.views.retain(|v| !(v.scene == progress.scene && v.view == progress.view));
        match self.pending.iter_mut().find(|p| p.scene == progress.scene && p.view == progress.view) {
            Some(old) => *old = progress,
            None => self.pending.push(progress),
        }
        Ok(())
    }

    /// The record of `scene`/`view`.
    pub fn get(&self, scene: &str, view: &str) -> Option<&ViewRecord> {
        self.views.iter().find(|v| v.scene == scene && v.view == view)
    }

    /// What is finished of `scene`/`view`: the finished record, else the pending one.
    pub fn progress(&self, scene: &str, view: &str) -> Option<PendingView> {
        self.get(scene, view)
            .cloned()
            .map(PendingView::from)
            .or_else(|| self.pending.iter().find(|p| p.scene == scene && p.view == view).cloned())
    }

    /// The views of one split.
    pub fn split(&self, split: Split) -> impl Iterator<Item = &ViewRecord> {
        self.views.iter().filter(move |v| v.split == split)
    }

    /// Every file a finished view consists of, relative to the root (noisy renders with their feature
    /// files and variance where recorded, the reference and the four features).
    pub fn files_of(view: &ViewRecord) -> Vec<String> {
        let mut files = Vec::new();
        for r in view.noisy.iter().chain(view.repeats.iter().flatten()) {
            files.push(r.file.clone());
            match &r.aux {
                Some(own) => files.extend(crate::AuxKind::ALL.iter().map(|&k| own.file(k).to_string())),
                None => {
                    for kind in crate::AuxKind::OIDN {
                        files.push(Layout::noisy_aux_name(&view.scene, &view.view, r.spp, kind));
                    }
                }
            }
            files.extend(r.variance.iter().cloned());
        }
        files.push(view.reference.file.clone());
        files.extend(crate::AuxKind::ALL.iter().map(|&k| view.aux.file(k).to_string()));
        files
    }
}

/// All manifest files of a dataset (`manifest.json` first, then the shard parts).
pub fn manifest_files(root: &Path) -> Result<Vec<PathBuf>> {
    let layout = Layout::new(root);
    let mut files = Vec::new();
    if layout.manifest_path().exists() {
        files.push(layout.manifest_path());
    }
    files.extend(layout.shard_manifest_paths()?);
    Ok(files)
}
