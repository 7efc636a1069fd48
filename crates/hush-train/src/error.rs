//! The one error type of hush-train.

use crate::Trained;

pub type Result<T, E = TrainError> = std::result::Result<T, E>;

#[derive(Debug, thiserror::Error)]
pub enum TrainError {
    /// The configuration cannot work (crop not a multiple of 16, channel counts that disagree, a
    /// checkpoint of another run, ...).
    #[error("invalid training configuration: {0}")]
    Config(String),
    /// The samples cannot be trained on (non-finite values, wrong sizes, ...).
    #[error("invalid training data: {0}")]
    Data(String),
    /// The loss or a gradient became NaN or infinite. Training stopped before the bad update, so
    /// `last_good` holds the weights and loss log of every step before `step`.
    #[error(
        "training stopped at step {step} (batch: {batch}): {cause}. The weights from before this step are \
         kept ({} logged steps).",
        last_good.log.len()
    )]
    Diverged { step: usize, batch: String, cause: String, last_good: Box<Trained> },
    /// Bytes that are not an intact sample cache of the expected key (see [`crate::decode_samples`]).
    #[error("unusable sample cache: {0}")]
    Cache(String),
    #[error(transparent)]
    Candle(#[from] candle_core::Error),
}
