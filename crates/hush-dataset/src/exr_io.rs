//! EXR reading and writing with named channel groups ("layers" in the OpenEXR sense of a name prefix).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use exr::prelude as x;
use exr::prelude::{ReadChannels as _, ReadLayers as _, WritableImage as _};

use crate::{Error, Image, Result, write_atomic};

/// Channel names of one entry given to [`write_exr`].
///
/// * prefix `""`: `R,G,B` (3 channels), `R,G,B,A` (4) or `Y` (1);
/// * prefix `"normal"`: `normal.X, normal.Y, normal.Z` (3 channels);
/// * any other prefix `p`: `p.R, p.G, p.B` (3), `p.R, p.G, p.B, p.A` (4) or `p.Y` (1).
pub fn channel_names(prefix: &str, channels: usize) -> Result<Vec<String>> {
    let suffixes: &[&str] = match (prefix, channels) {
        ("normal", 3) => &["X", "Y", "Z"],
        ("normal", _) => {
            return Err(Error::Shape(format!("layer \"normal\" needs 3 channels (X, Y, Z), got {channels}")));
        }
        (_, 1) => &["Y"],
        (_, 3) => &["R", "G", "B"],
        (_, 4) => &["R", "G", "B", "A"],
        _ => {
            return Err(Error::Shape(format!(
                "layer {prefix:?} has {channels} channels; EXR layers written by hush have 1 (Y), 3 (RGB) or 4 (RGBA)"
            )));
        }
    };
    Ok(suffixes.iter().map(|s| if prefix.is_empty() { s.to_string() } else { format!("{prefix}.{s}") }).collect())
}

/// Writes one single-part EXR file holding every `(prefix, image)` entry as 32-bit float channels named by
/// [`channel_names`]. All images must have the same width and height. ZIP compression, written atomically.
///
/// ```
/// # fn main() -> hush_dataset::Result<()> {
/// use hush_dataset::{read_exr, write_exr, Image};
/// let dir = std::env::temp_dir().join(format!("hush-doc-exr-{}", std::process::id()));
/// std::fs::create_dir_all(&dir)?;
/// let path = dir.join("frame.exr");
/// let color = Image::from_fn(4, 2, 3, |x, y, c| (x + y + c) as f32);
/// let normal = Image::from_fn(4, 2, 3, |_, _, c| if c == 2 { 1.0 } else { 0.0 });
/// write_exr(&path, &[("", &color), ("normal", &normal)])?;
///
/// let exr = read_exr(&path)?;
/// assert!(exr.channels.contains_key("normal.Z"));
/// assert_eq!(exr.layer("")?, color);
/// assert_eq!(exr.layer("normal")?, normal);
/// # std::fs::remove_dir_all(&dir)?;
/// # Ok(())
/// # }
/// ```
pub fn write_exr(path: impl AsRef<Path>, layers: &[(&str, &Image)]) -> Result<()> {
    let path = path.as_ref();
    let Some((_, first)) = layers.first() else {
        return Err(Error::Shape(format!("{}: write_exr needs at least one layer", path.display())));
    };
    let (width, height) = (first.width, first.height);
    if width == 0 || height == 0 {
        return Err(Error::Shape(format!("{}: cannot write an empty {} image", path.display(), first.size_string())));
    }
    let mut list: Vec<x::AnyChannel<x::FlatSamples>> = Vec::new();
    let mut seen = std::collections::BTreeSet::new();
    for (prefix, image) in layers {
        if (image.width, image.height) != (width, height) {
            return Err(Error::Shape(format!(
                "{}: layer {prefix:?} is {} but the first layer is {}; all layers of an EXR file must have the same size",
                path.display(),
                image.size_string(),
                first.size_string()
            )));
        }
        let names =
            channel_names(prefix, image.channels).map_err(|e| Error::Shape(format!("{}: {e}", path.display())))?;
        for (c, name) in names.into_iter().enumerate() {
            if !seen.insert(name.clone()) {
                return Err(Error::Shape(format!("{}: channel {name} would be written twice", path.display())));
            }
            let samples: Vec<f32> = image.data.iter().skip(c).step_by(image.channels).copied().collect();
            list.push(x::AnyChannel::new(name.as_str(), x::FlatSamples::F32(samples)));
        }
    }
    let channels = x::AnyChannels::sort(x::SmallVec::from_vec(list));
    let layer = x::Layer::new((width, height), x::LayerAttributes::default(), x::Encoding::SMALL_LOSSLESS, channels);
    let image = x::Image::from_layer(layer);
    write_atomic(path, |tmp| {
        image.write().to_file(tmp).map_err(|source| Error::Exr { path: path.to_path_buf(), action: "writing", source })
    })
}

/// Writes one RGB (3 channels) or Y (1 channel) image as plain `R,G,B` / `Y` channels, the way Open Image
/// Denoise's training tools expect every feature file (`.hdr.exr`, `.alb.exr`, `.nrm.exr`).
pub fn write_rgb(path: impl AsRef<Path>, image: &Image) -> Result<()> {
    write_exr(path, &[("", image)])
}

/// The channels of an EXR file, each converted to f32 and stored row-major.
#[derive(Clone, Debug, PartialEq)]
pub struct ExrImage {
    /// The file it was read from (for messages).
    pub path: PathBuf,
    pub width: usize,
    pub height: usize,
    /// Full channel name (`"R"`, `"normal.X"`, ...) → samples, row-major.
    pub channels: BTreeMap<String, Vec<f32>>,
}

impl ExrImage {
    /// Gathers the channels of one layer into an [`Image`]: for prefix `p` (`""` for the beauty image) the first
    /// group present among `p.R,p.G,p.B`, `p.X,p.Y,p.Z` and `p.Y` (single channel). Suffixes also match in
    /// lower case. Fails with the list of available channels when none is present.
    pub fn layer(&self, prefix: &str) -> Result<Image> {
        const GROUPS: [&[&str]; 3] = [&["R", "G", "B"], &["X", "Y", "Z"], &["Y"]];
        let full = |s: &str| {
            if prefix.is_empty() { s.to_string() } else { format!("{prefix}.{s}") }
        };
        for group in GROUPS {
            let found: Option<Vec<&Vec<f32>>> = group
                .iter()
                .map(|s| self.channels.get(&full(s)).or_else(|| self.channels.get(&full(&s.to_lowercase()))))
                .collect();
            if let Some(found) = found {
                let c = found.len();
                let mut data = vec![0.0; self.width * self.height * c];
                for (k, samples) in found.into_iter().enumerate() {
                    for (dst, &v) in data.iter_mut().skip(k).step_by(c).zip(samples) {
                        *dst = v;
                    }
                }
                return Image::new(self.width, self.height, c, data);
            }
        }
        Err(Error::MissingChannels {
            path: self.path.clone(),
            prefix: prefix.to_string(),
            wanted: GROUPS.map(|g| g.iter().map(|s| full(s)).collect::<Vec<_>>().join(",")).join(" or "),
            available: self.channels.keys().cloned().collect::<Vec<_>>().join(", "),
        })
    }
}

/// The most samples (pixels × channels, summed over an EXR file's parts) hush decodes from one file unless
/// `HUSH_MAX_EXR_SAMPLES` says otherwise: 2^29, i.e. 2 GiB as f32, a 16384×8192 RGBA environment map.
pub const MAX_EXR_SAMPLES: u64 = 1 << 29;

/// [`MAX_EXR_SAMPLES`], or the value of `HUSH_MAX_EXR_SAMPLES` where it is set to a number.
pub fn max_exr_samples() -> u64 {
    hush_io::limit_from_env("HUSH_MAX_EXR_SAMPLES", MAX_EXR_SAMPLES)
}

/// The samples an EXR file's header declares (pixels × channels over every part), read without decoding any
/// pixel; refused with an error naming the file and the limit when above [`max_exr_samples`]. The decoder
/// allocates every channel from the header alone, so a file of a few hundred bytes can otherwise ask for
/// tens of gigabytes.
pub fn check_exr_header(path: &Path) -> Result<u64> {
    let meta = exr::meta::MetaData::read_from_file(path, false).map_err(|source| Error::Exr {
        path: path.to_path_buf(),
        action: "reading the header of",
        source,
    })?;
    let mut samples: u64 = 0;
    for header in &meta.headers {
        let (w, h) = (header.layer_size.width() as u64, header.layer_size.height() as u64);
        let part = w.saturating_mul(h).saturating_mul(header.channels.list.len() as u64);
        samples = samples.saturating_add(part);
    }
    let max = max_exr_samples();
    if samples > max {
        let sizes: Vec<String> = meta
            .headers
            .iter()
            .map(|h| {
                format!("{}x{} with {} channels", h.layer_size.width(), h.layer_size.height(), h.channels.list.len())
            })
            .collect();
        return Err(Error::Shape(format!(
            "{}: the EXR header declares {} ({samples} samples), above hush's limit of {max}; refused before \
             decoding. If the image is real, raise the limit with HUSH_MAX_EXR_SAMPLES=<samples>",
            path.display(),
            sizes.join(", ")
        )));
    }
    Ok(samples)
}

/// Reads every channel of every part of an EXR file (half, float and uint samples become f32). In a
/// multi-part file, the channels of a named part `n` are keyed `n.<channel>`; all parts must have the same size.
/// A header that declares more than [`max_exr_samples`] is refused before anything is decoded.
pub fn read_exr(path: impl AsRef<Path>) -> Result<ExrImage> {
    let path = path.as_ref();
    if let Some(why) = hush_io::describe_unreadable(path) {
        return Err(Error::file(
            path,
            "read EXR",
            std::io::Error::new(why.kind(), format!("{why}; check the path or re-create the dataset")),
        ));
    }
    check_exr_header(path)?;
    let image = x::read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .all_layers()
        .all_attributes()
        .from_file(path)
        .map_err(|source| Error::Exr { path: path.to_path_buf(), action: "reading", source })?;
    let parts = image.layer_data.len();
    let mut out = ExrImage { path: path.to_path_buf(), width: 0, height: 0, channels: BTreeMap::new() };
    for (i, layer) in image.layer_data.iter().enumerate() {
        let (w, h) = (layer.size.width(), layer.size.height());
        if i == 0 {
            (out.width, out.height) = (w, h);
        } else if (w, h) != (out.width, out.height) {
            return Err(Error::Shape(format!(
                "{}: part {i} is {w}x{h} but part 0 is {}x{}; hush reads only parts of one size",
                path.display(),
                out.width,
                out.height
            )));
        }
        let part_name = layer.attributes.layer_name.as_ref().map(|t| t.to_string());
        for channel in &layer.channel_data.list {
            let mut name = channel.name.to_string();
            if let Some(part) = part_name.as_deref().filter(|_| parts > 1) {
                name = format!("{part}.{name}");
            }
            let samples: Vec<f32> = channel.sample_data.values_as_f32().collect();
            out.channels.insert(name, samples);
        }
    }
    Ok(out)
}

/// Reads the beauty (`R,G,B`) image of an EXR file.
pub fn read_rgb(path: impl AsRef<Path>) -> Result<Image> {
    read_exr(path)?.layer("")
}
