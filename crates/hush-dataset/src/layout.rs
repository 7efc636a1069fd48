//! The on-disk dataset: file names (Open Image Denoise's training-toolkit convention) and `manifest.json`.
//!
//! ```text
//! <root>/manifest.json                    the manifest (see [`crate::Manifest`])
//! <root>/manifest.shard-2-of-8.json       one shard's part of it (`hush dataset --shard 2/8`)
//! <root>/<scene>_<view>_000004.hdr.exr     noisy renders, one per spp (R,G,B)
//! <root>/<scene>_<view>_000004.alb.exr     the noisy render's own albedo, normal, diffuse and specular, at its
//! <root>/<scene>_<view>_000004.nrm.exr       spp (OIDN's toolkit reads `.alb` and `.nrm` beside every noisy
//! <root>/<scene>_<view>_000004.diff.exr      render). Datasets from before these were stored hold hard links
//! <root>/<scene>_<view>_000004.spec.exr      to the clean `_ref` features under the first two names instead
//! <root>/<scene>_<view>_000004.var.exr     the variance of each pixel of that noisy render (R,G,B; none in
//!                                            datasets from before it was stored)
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

use crate::{Error, Image, RenderRecord, Result, ViewRecord, check_finite, read_rgb};

/// Where the files of a dataset live and what they are called.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Layout {
    root: PathBuf,
}

/// Which auxiliary images go with a noisy render: its own (`Noisy`, at its spp: what a user denoising a render
/// has, OIDN's default) or the view's clean ones (`Clean`: rendered once per view at `--aux-spp`; OIDN's
/// `clean_aux`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum AuxSource {
    #[default]
    Noisy,
    Clean,
}

impl AuxSource {
    pub fn name(self) -> &'static str {
        match self {
            AuxSource::Noisy => "noisy",
            AuxSource::Clean => "clean",
        }
    }

    /// `noisy` or `clean`.
    pub fn parse(s: &str) -> Option<AuxSource> {
        [AuxSource::Noisy, AuxSource::Clean].into_iter().find(|a| a.name() == s)
    }

    /// How a report says which were used.
    pub fn describe(self) -> &'static str {
        match self {
            AuxSource::Noisy => "each noisy render's own auxiliary images, at its spp",
            AuxSource::Clean => "the view's clean auxiliary images (--aux-spp samples)",
        }
    }
}

impl std::fmt::Display for AuxSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// The auxiliary features stored per view (clean) and per noisy render (its own).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum AuxKind {
    Albedo,
    Normal,
    Diffuse,
    Specular,
}

impl AuxKind {
    pub const ALL: [AuxKind; 4] = [AuxKind::Albedo, AuxKind::Normal, AuxKind::Diffuse, AuxKind::Specular];
    /// The features OIDN's toolkit reads beside every noisy render.
    pub const OIDN: [AuxKind; 2] = [AuxKind::Albedo, AuxKind::Normal];

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
        self.root.join(crate::Manifest::FILE_NAME)
    }

    /// `<root>/manifest.shard-<index>-of-<count>.json`: the part written by `--shard index/count`.
    pub fn shard_manifest_path(&self, index: u32, count: u32) -> PathBuf {
        self.root.join(format!("manifest.shard-{index}-of-{count}.json"))
    }

    /// The shard parts present in `root`, sorted by name.
    pub fn shard_manifest_paths(&self) -> Result<Vec<PathBuf>> {
        let mut parts = Vec::new();
        let entries = match std::fs::read_dir(&self.root) {
            Ok(e) => e,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(parts),
            Err(e) => return Err(Error::file(&self.root, "list the dataset folder", e)),
        };
        for entry in entries {
            let entry = entry.map_err(|e| Error::file(&self.root, "list the dataset folder", e))?;
            let name = entry.file_name().to_string_lossy().into_owned();
            if name.starts_with("manifest.shard-") && name.ends_with(".json") {
                parts.push(entry.path());
            }
        }
        parts.sort();
        Ok(parts)
    }

    /// `<root>/<file>` for a file name stored in the manifest.
    pub fn path(&self, file: &str) -> PathBuf {
        self.root.join(file)
    }

    /// `<scene>_<view>_<spp:06>.hdr.exr`.
    pub fn noisy_name(scene: &str, view: &str, spp: u32) -> String {
        format!("{scene}_{view}_{spp:06}.hdr.exr")
    }

    /// `<scene>_<view>_<spp:06>.var.exr`: the variance of each pixel of that noisy render's beauty.
    pub fn noisy_variance_name(scene: &str, view: &str, spp: u32) -> String {
        format!("{scene}_{view}_{spp:06}.var.exr")
    }

    /// The folder of the repeated renders (`hush dataset --test-repeats`), relative to the root: out of the
    /// way of Open Image Denoise's toolkit, which reads the root's `<name>_<spp>.<feature>.exr` files.
    pub const REPEATS: &'static str = "repeats";

    /// `repeats/<scene>_<view>_<spp:06>_r<k>.<ext>.exr`: the beauty (`hdr`), a feature of [`AuxKind`] or the
    /// variance (`var`) of repeat `k` of the noisy render at `spp`.
    pub fn repeat_name(scene: &str, view: &str, spp: u32, k: u32, ext: &str) -> String {
        format!("{}/{scene}_{view}_{spp:06}_r{k}.{ext}.exr", Self::REPEATS)
    }

    /// `<scene>_<view>_ref.hdr.exr`.
    pub fn reference_name(scene: &str, view: &str) -> String {
        format!("{scene}_{view}_ref.hdr.exr")
    }

    /// `<scene>_<view>_<spp:06>.<alb|nrm>.exr`: the clean feature beside a noisy render, where Open Image
    /// Denoise's training toolkit looks for it.
    pub fn noisy_aux_name(scene: &str, view: &str, spp: u32, kind: AuxKind) -> String {
        format!("{scene}_{view}_{spp:06}.{}.exr", kind.extension())
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

/// The images of one view at one spp, all of the same size and free of NaN/Inf.
#[derive(Clone, Debug)]
pub struct ViewImages {
    pub color: Image,
    pub albedo: Image,
    pub normal: Image,
    pub diffuse: Image,
    pub specular: Image,
    pub reference: Image,
    /// The variance of the noisy render's pixel values, where the dataset stores it (renders made before
    /// hush wrote variance files have none).
    pub variance: Option<Image>,
}

/// Loads the noisy render at `spp`, the auxiliary images `aux` names and the reference of `view` from `root`.
/// Fails if the spp is not stored (listing those that are), if the render's own auxiliary images are asked for
/// but the dataset predates them (saying how to add them), if a file is missing, if the sizes differ from each
/// other or from the camera (naming the files and sizes), or if any image holds NaN/Inf.
pub fn load_view(root: impl AsRef<Path>, view: &ViewRecord, spp: u32, aux: AuxSource) -> Result<ViewImages> {
    load_view_with(root, view, spp, aux, false)
}

/// [`load_view`], also reading the noisy render's variance where `variance` is set and the dataset stores one
/// (only a model that takes the variance needs it, so a lost or broken variance file stops no other).
pub fn load_view_with(
    root: impl AsRef<Path>,
    view: &ViewRecord,
    spp: u32,
    aux: AuxSource,
    variance: bool,
) -> Result<ViewImages> {
    let noisy = view.noisy_at(spp).ok_or_else(|| {
        Error::Dataset(format!(
            "view {}_{} has no noisy render at {spp} spp; stored: {:?}. Render it or pick a stored spp",
            view.scene,
            view.view,
            view.noisy.iter().map(|r| r.spp).collect::<Vec<_>>()
        ))
    })?;
    load_render_with(root, view, noisy, aux, variance, None)
}

/// [`load_view_with`] for one render of `view` (its noisy render at some spp or a repeat of it,
/// [`ViewRecord::renders_at`]). `reference`: the view's reference as an earlier load returned it, so that a
/// caller going through several renders of a view reads it once; `None` reads its file. Either way its size
/// is checked with the files'.
pub fn load_render_with(
    root: impl AsRef<Path>,
    view: &ViewRecord,
    noisy: &RenderRecord,
    aux: AuxSource,
    variance: bool,
    reference: Option<Image>,
) -> Result<ViewImages> {
    let layout = Layout::new(root.as_ref());
    let spp = noisy.spp;
    let features = match aux {
        AuxSource::Clean => AuxKind::ALL.map(|k| view.aux.file(k)),
        AuxSource::Noisy => match &noisy.aux {
            Some(own) => AuxKind::ALL.map(|k| own.file(k)),
            None => {
                return Err(Error::Dataset(format!(
                    "view {}_{} at {spp} spp in {}: the dataset stores no auxiliary images of the render itself \
                     (it was made before hush stored them); run `hush dataset` again with the same arguments to \
                     add them (it re-renders only the noisy images), or use the clean ones (--aux clean)",
                    view.scene,
                    view.view,
                    layout.root().display()
                )));
            }
        },
    };
    let reference_file = view.reference.file.as_str();
    let files = [noisy.file.as_str(), features[0], features[1], features[2], features[3], reference_file];
    let files: Vec<&str> = files.into_iter().chain(noisy.variance.as_deref().filter(|_| variance)).collect();
    let mut reference = reference;
    let mut images = Vec::with_capacity(files.len());
    for &file in &files {
        if file == reference_file
            && let Some(given) = reference.take()
        {
            images.push(given);
            continue;
        }
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
        variance: it.next(),
    })
}
