//! AOV images, EXR/PFM/PNG I/O and the on-disk dataset layout of hush. No GPU, no Candle.
//!
//! * [`Image`]: an interleaved (HWC) f32 image with crop, channel stacking and statistics.
//! * [`write_exr`] / [`read_exr`]: named channel groups in one EXR file (`R,G,B`, `normal.X`, `albedo.R`, ...).
//! * [`write_pfm`] / [`read_pfm`]: RGB or one-channel PFM files, the format of OIDN's command-line tools.
//! * [`write_png_preview`]: an 8-bit sRGB preview.
//! * [`write_atomic`]: every file this crate writes appears complete or not at all.
//! * [`check_finite`] / [`check_radiance`]: NaN/Inf and negative-radiance checks that name the pixel.
//! * [`Layout`], [`Manifest`], [`load_view`]: the dataset directory (Open Image Denoise's file naming)
//!   and its `manifest.json` (merged from shard parts on read).
//! * [`despeckle`]: the firefly filter of references; [`check_dataset`]: completeness and validity.
//!
//! ```
//! # fn main() -> hush_dataset::Result<()> {
//! use hush_dataset::{check_finite, read_rgb, write_png_preview, write_rgb, Image};
//!
//! let dir = std::env::temp_dir().join(format!("hush-doc-lib-{}", std::process::id()));
//! std::fs::create_dir_all(&dir)?;
//! let color = Image::from_fn(8, 8, 3, |x, y, _| (x * y) as f32 / 64.0);
//! write_rgb(dir.join("cbox_v0_000016.hdr.exr"), &color)?;
//! write_png_preview(dir.join("cbox_v0_000016.png"), &color, 1.0)?;
//!
//! let back = read_rgb(dir.join("cbox_v0_000016.hdr.exr"))?;
//! check_finite("cbox_v0_000016.hdr.exr", &back)?;
//! assert_eq!(back.crop(2, 2, 4, 4)?, color.crop(2, 2, 4, 4)?);
//! # std::fs::remove_dir_all(&dir)?;
//! # Ok(())
//! # }
//! ```

mod atomic;
mod check;
mod error;
mod exr_io;
mod firefly;
mod image;
mod layout;
mod manifest;
mod pfm;
mod png;
mod validate;

pub use atomic::write_atomic;
pub use check::{CheckReport, check_dataset, check_image, link_or_copy, temp_files, temp_target};
pub use error::{Error, Result};
pub use exr_io::{
    ExrImage, MAX_EXR_SAMPLES, channel_names, check_exr_header, max_exr_samples, read_exr, read_rgb, write_exr,
    write_rgb,
};
pub use firefly::{DEFAULT_FIREFLY_FACTOR, DespeckleStats, despeckle, luminance};
pub use image::Image;
pub use layout::{AuxKind, AuxSource, Layout, ViewImages, load_render_with, load_view, load_view_with};
pub use manifest::{
    AuxFiles, AuxRecord, CameraRecord, DatasetConfig, FireflyRecord, Manifest, PendingView, ProbeRecord,
    ProceduralRecord, ProceduralScene, ReferenceCheck, ReferenceRecord, RenderRecord, SceneEntry, SkippedScene, Split,
    ViewGeneration, ViewRecord, manifest_files, max_manifest_bytes,
};
pub use pfm::{read_pfm, write_pfm};
pub use png::{srgb_encode, write_png_preview};
pub use validate::{NegativePolicy, check_finite, check_radiance};
