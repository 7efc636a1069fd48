//! The on-disk dataset: file names (Open Image Denoise's training-toolkit convention) and `manifest.json`.
//!
//! ```text
//! <root>/manifest.json
//! <root>/<scene>_<view>_000004.hdr.exr     noisy renders, one per spp (R,G,B)
//! <root>/<scene>_<view>_ref.hdr.exr        the reference (R,G,B)
//! <root>/<scene>_<view>_ref.alb.exr        clean albedo (R,G,B)
//! <root>/<scene>_<view>_ref.nrm.exr        clean shading normal (R,G,B = x,y,z)
//! <root>/<scene>_<view>_ref.diff.exr       clean diffuse (R,G,B)
//! <root>/<scene>_<view>_ref.spec.exr       clean specular (R,G,B)
//! ```
//!
//! OIDN's toolkit groups files by the name up to the last `_`, so `<scene>_<view>` is one group; that is why
//! scene and view names may not contain `_` (nor `.`, `/` or whitespace), see [`Layout::check_name`].

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::{Error, Image, Result, check_finite, read_rgb, write_atomic};

/// Where the files of a dataset live and what they are called.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Layout {
    root: PathBuf,
}

/// The clean auxiliary features stored once per view.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum AuxKind {
    Albedo,
    Normal,
    Diffuse,
    Specular,
}

impl AuxKind {
    pub const ALL: [AuxKind; 4] = [AuxKind::Albedo, AuxKind::Normal, AuxKind::Diffuse, AuxKind::Specular];

    /// The feature part of the file name: `alb`, `nrm`, `diff`, `spec`.
    pub fn extension(self) -> &'static str {
        match self {
            AuxKind::Albedo => "alb",
            AuxKind::Normal => "nrm",
            AuxKind::Diffuse => "diff",
            AuxKind::Specular => "spec",
        }
    }
}

impl Layout {
    pub fn new(root: impl Into<PathBuf>) -> Self {
        Layout { root: root.into() }
    }

    pub fn root(&self) -> &Path {
        &self.root
    }

    /// `<root>/manifest.json`.
    pub fn manifest_path(&self) -> PathBuf {
        self.root.join(Manifest::FILE_NAME)
    }

    /// `<root>/<file>` for a file name stored in the manifest.
    pub fn path(&self, file: &str) -> PathBuf {
        self.root.join(file)
    }

    /// `<scene>_<view>_<spp:06>.hdr.exr`.
    pub fn noisy_name(scene: &str, view: &str, spp: u32) -> String {
        format!("{scene}_{view}_{spp:06}.hdr.exr")
    }

    /// `<scene>_<view>_ref.hdr.exr`.
    pub fn reference_name(scene: &str, view: &str) -> String {
        format!("{scene}_{view}_ref.hdr.exr")
    }

    /// `<scene>_<view>_ref.<alb|nrm|diff|spec>.exr`.
    pub fn aux_name(scene: &str, view: &str, kind: AuxKind) -> String {
        format!("{scene}_{view}_ref.{}.exr", kind.extension())
    }

    /// Scene and view names: non-empty ASCII letters, digits and `-`.
    pub fn check_name(what: &str, name: &str) -> Result<()> {
        if name.is_empty() || !name.bytes().all(|b| b.is_ascii_alphanumeric() || b == b'-') {
            return Err(Error::Dataset(format!(
                "{what} name {name:?} must be non-empty ASCII letters, digits and '-' \
                 (no '_' or '.': they separate the parts of OIDN-style file names); e.g. use \"cornell-box\""
            )));
        }
        Ok(())
    }
}

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
    pub render_seconds: f64,
}

/// The clean auxiliary images of a view, rendered together.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct AuxRecord {
    pub spp: u32,
    pub seed: u64,
    pub render_seconds: f64,
    pub albedo: String,
    pub normal: String,
    pub diffuse: String,
    pub specular: String,
}

impl AuxRecord {
    /// The file of one feature.
    pub fn file(&self, kind: AuxKind) -> &str {
        match kind {
            AuxKind::Albedo => &self.albedo,
            AuxKind::Normal => &self.normal,
            AuxKind::Diffuse => &self.diffuse,
            AuxKind::Specular => &self.specular,
        }
    }
}

/// Everything stored for one camera view of one scene.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ViewRecord {
    pub scene: String,
    pub view: String,
    pub split: Split,
    pub camera: CameraRecord,
    /// Noisy renders, one per spp, sorted by spp.
    pub noisy: Vec<RenderRecord>,
    pub reference: RenderRecord,
    pub aux: AuxRecord,
}

impl ViewRecord {
    /// The noisy render at `spp`, if stored.
    pub fn noisy_at(&self, spp: u32) -> Option<&RenderRecord> {
        self.noisy.iter().find(|r| r.spp == spp)
    }

    /// Checks the names and that no spp appears twice.
    pub fn validate(&self) -> Result<()> {
        Layout::check_name("scene", &self.scene)?;
        Layout::check_name("view", &self.view)?;
        let mut spps: Vec<u32> = self.noisy.iter().map(|r| r.spp).collect();
        spps.sort_unstable();
        if let Some(w) = spps.windows(2).find(|w| w[0] == w[1]) {
            return Err(Error::Dataset(format!(
                "view {}_{} lists two noisy renders at {} spp",
                self.scene, self.view, w[0]
            )));
        }
        Ok(())
    }
}

/// `manifest.json` at the dataset root: every view and how it was rendered.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    pub format_version: u32,
    pub views: Vec<ViewRecord>,
}

impl Default for Manifest {
    fn default() -> Self {
        Manifest { format_version: Self::FORMAT_VERSION, views: Vec::new() }
    }
}

impl Manifest {
    pub const FORMAT_VERSION: u32 = 1;
    pub const FILE_NAME: &'static str = "manifest.json";

    /// Reads `<root>/manifest.json`; fails if it is missing, malformed or of another format version.
    pub fn load(root: impl AsRef<Path>) -> Result<Self> {
        let path = Layout::new(root.as_ref()).manifest_path();
        let text = std::fs::read_to_string(&path).map_err(|e| {
            Error::file(&path, "read the dataset manifest (is this a dataset root? render one first)", e)
        })?;
        let manifest: Manifest = serde_json::from_str(&text).map_err(|source| Error::Json {
            path: path.clone(),
            action: "parsing",
            source,
        })?;
        if manifest.format_version != Self::FORMAT_VERSION {
            return Err(Error::Dataset(format!(
                "{}: format_version {} but this build reads {}; re-create the dataset with this build",
                path.display(),
                manifest.format_version,
                Self::FORMAT_VERSION
            )));
        }
        for v in &manifest.views {
            v.validate().map_err(|e| Error::Dataset(format!("{}: {e}", path.display())))?;
        }
        Ok(manifest)
    }

    /// Like [`Manifest::load`], but an empty manifest if the file does not exist yet.
    pub fn load_or_default(root: impl AsRef<Path>) -> Result<Self> {
        if Layout::new(root.as_ref()).manifest_path().exists() { Self::load(root) } else { Ok(Self::default()) }
    }

    /// Writes `<root>/manifest.json` atomically (pretty-printed, views sorted by scene and view).
    pub fn save(&self, root: impl AsRef<Path>) -> Result<()> {
        let path = Layout::new(root.as_ref()).manifest_path();
        let mut sorted = self.clone();
        sorted.views.sort_by(|a, b| (&a.scene, &a.view).cmp(&(&b.scene, &b.view)));
        let mut text = serde_json::to_string_pretty(&sorted).map_err(|source| Error::Json {
            path: path.clone(),
            action: "writing",
            source,
        })?;
        text.push('\n');
        write_atomic(&path, |tmp| std::fs::write(tmp, &text).map_err(|e| Error::file(&path, "write", e)))
    }

    /// Inserts `view`, replacing the record with the same scene and view; returns the replaced one.
    pub fn upsert(&mut self, mut view: ViewRecord) -> Result<Option<ViewRecord>> {
        view.validate()?;
        view.noisy.sort_by_key(|r| r.spp);
        match self.views.iter_mut().find(|v| v.scene == view.scene && v.view == view.view) {
            Some(old) => Ok(Some(std::mem::replace(old, view))),
            None => {
                self.views.push(view);
                Ok(None)
            }
        }
    }

    /// The record of `scene`/`view`.
    pub fn get(&self, scene: &str, view: &str) -> Option<&ViewRecord> {
        self.views.iter().find(|v| v.scene == scene && v.view == view)
    }

    /// The views of one split.
    pub fn split(&self, split: Split) -> impl Iterator<Item = &ViewRecord> {
        self.views.iter().filter(move |v| v.split == split)
    }
}

/// The images of one view at one spp, all of the same size and free of NaN/Inf.
#[derive(Clone, Debug)]
pub struct ViewImages {
    pub color: Image,
    pub albedo: Image,
    pub normal: Image,
    pub diffuse: Image,
    pub specular: Image,
    pub reference: Image,
}

/// Loads the noisy render at `spp`, the clean auxiliary images and the reference of `view` from `root`.
/// Fails if the spp is not stored (listing those that are), if a file is missing, if the sizes differ from each
/// other or from the camera (naming the files and sizes), or if any image holds NaN/Inf.
pub fn load_view(root: impl AsRef<Path>, view: &ViewRecord, spp: u32) -> Result<ViewImages> {
    let layout = Layout::new(root.as_ref());
    let noisy = view.noisy_at(spp).ok_or_else(|| {
        Error::Dataset(format!(
            "view {}_{} has no noisy render at {spp} spp; stored: {:?}. Render it or pick a stored spp",
            view.scene,
            view.view,
            view.noisy.iter().map(|r| r.spp).collect::<Vec<_>>()
        ))
    })?;
    let files = [
        noisy.file.as_str(),
        view.aux.albedo.as_str(),
        view.aux.normal.as_str(),
        view.aux.diffuse.as_str(),
        view.aux.specular.as_str(),
        view.reference.file.as_str(),
    ];
    let mut images = Vec::with_capacity(files.len());
    for file in files {
        let path = layout.path(file);
        let image = read_rgb(&path)?;
        if image.channels != 3 {
            return Err(Error::Shape(format!(
                "{}: expected 3 channels (R,G,B), found a {} image",
                path.display(),
                image.size_string()
            )));
        }
        check_finite(&path, &image)?;
        images.push(image);
    }
    let (cw, ch) = (view.camera.width as usize, view.camera.height as usize);
    if images.iter().any(|im| (im.width, im.height) != (cw, ch)) {
        let sizes: Vec<String> =
            files.iter().zip(&images).map(|(f, im)| format!("{f}: {}x{}", im.width, im.height)).collect();
        return Err(Error::Shape(format!(
            "view {}_{} in {}: the camera is {cw}x{ch} but the files are [{}]; re-render the mismatched files",
            view.scene,
            view.view,
            layout.root().display(),
            sizes.join(", ")
        )));
    }
    let mut it = images.into_iter();
    let mut next = || it.next().expect("six images were read");
    Ok(ViewImages {
        color: next(),
        albedo: next(),
        normal: next(),
        diffuse: next(),
        specular: next(),
        reference: next(),
    })
}
