use std::path::PathBuf;

/// `Result` with this crate's [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// Errors of hush-eval.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// Images disagree in size or channel count, or an argument is out of range.
    #[error("{0}")]
    Shape(String),

    /// An image holds NaN/Inf (which image and where is in the message).
    #[error("{0}")]
    NonFinite(#[source] hush_dataset::Error),

    /// Reading or writing files.
    #[error(transparent)]
    Dataset(#[from] hush_dataset::Error),

    /// SSIM through hush-net failed.
    #[error("SSIM (hush-net): {0}")]
    Candle(#[from] candle_core::Error),

    /// An I/O error on a known file.
    #[error("{}: cannot {action}: {source}", path.display())]
    File { path: PathBuf, action: &'static str, source: std::io::Error },

    /// An I/O error without a known file (from `write_atomic`, whose messages name the file).
    #[error(transparent)]
    Io(#[from] std::io::Error),

    /// Drawing or encoding a plot or picture.
    #[error("{0}")]
    Picture(String),

    /// A JSON file (an evaluation summary, a sweep plan) does not parse.
    #[error("{}: not the JSON hush expects ({source}); rewrite it with the command that made it", path.display())]
    ReadJson { path: PathBuf, source: serde_json::Error },

    /// Serializing the JSON summary failed.
    #[error("{}: writing JSON failed: {source}", path.display())]
    Json { path: PathBuf, source: serde_json::Error },
}
