//! The one error type of this crate. Every variant that concerns a file names it.

use std::path::PathBuf;

/// `Result` with this crate's [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// What went wrong, which file it concerns and, where there is one, how to fix it.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// An I/O error on a known file.
    #[error("{}: cannot {action}: {source}", path.display())]
    File { path: PathBuf, action: &'static str, source: std::io::Error },

    /// An I/O error from a caller's closure (see [`crate::write_atomic`]).
    #[error(transparent)]
    Io(#[from] std::io::Error),

    /// The EXR decoder or encoder failed.
    #[error("{}: {action} EXR failed: {source}", path.display())]
    Exr { path: PathBuf, action: &'static str, source: exr::error::Error },

    /// The PNG encoder failed.
    #[error("{}: writing PNG failed: {source}", path.display())]
    Png { path: PathBuf, source: image::ImageError },

    /// A JSON file could not be parsed or written.
    #[error("{}: {action} JSON failed: {source}", path.display())]
    Json { path: PathBuf, action: &'static str, source: serde_json::Error },

    /// Image sizes or channel counts disagree, or an argument is out of range.
    #[error("{0}")]
    Shape(String),

    /// An EXR file lacks the channels asked for.
    #[error(
        "{}: no channels for layer {prefix:?} (looked for {wanted}); available channels: [{available}]. \
         Write the file with write_exr(path, &[({prefix:?}, &image)]) or ask for one of the available layers",
        path.display()
    )]
    MissingChannels { path: PathBuf, prefix: String, wanted: String, available: String },

    /// NaN or infinite samples.
    #[error(
        "{}: {count} non-finite sample(s) (NaN/Inf); first at pixel (x {x}, y {y}), channel {channel}: {value}. \
         Fix the producer (renderer) or re-render this image",
        path.display()
    )]
    NonFinite { path: PathBuf, count: usize, x: usize, y: usize, channel: usize, value: f32 },

    /// Negative samples in an image that holds radiance.
    #[error(
        "{}: {count} negative radiance sample(s); first at pixel (x {x}, y {y}), channel {channel}: {value}. \
         Radiance must be >= 0: fix the renderer, or pass NegativePolicy::Clamp to clamp them to 0",
        path.display()
    )]
    Negative { path: PathBuf, count: usize, x: usize, y: usize, channel: usize, value: f32 },

    /// The dataset (manifest, names, records) is inconsistent.
    #[error("{0}")]
    Dataset(String),
}

impl Error {
    pub(crate) fn file(path: impl Into<PathBuf>, action: &'static str, source: std::io::Error) -> Self {
        Error::File { path: path.into(), action, source }
    }
}
