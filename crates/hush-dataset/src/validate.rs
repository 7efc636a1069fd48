//! Checks for NaN/Inf and negative radiance, with messages that point at the file and the pixel.

use std::path::Path;

use crate::{Error, Image, Result};

/// Fails if `image` holds NaN or ±Inf, naming `path` (used only for the message), the number of bad
/// samples and the first one as (x, y, channel).
pub fn check_finite(path: impl AsRef<Path>, image: &Image) -> Result<()> {
    match image.find_first(|v| !v.is_finite()) {
        None => Ok(()),
        Some((x, y, channel, value)) => Err(Error::NonFinite {
            path: path.as_ref().to_path_buf(),
            count: image.count_non_finite(),
            x,
            y,
            channel,
            value,
        }),
    }
}

/// What to do with negative samples in radiance (color, diffuse, specular, reference).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum NegativePolicy {
    /// Fail, naming the first negative pixel. Radiance is never negative, so a negative value is a bug.
    #[default]
    Error,
    /// Clamp negative samples to 0 (what Open Image Denoise's toolkit does on load).
    Clamp,
}

/// Checks a radiance image: fails on NaN/Inf (always), then applies `policy` to negative samples.
/// Returns how many samples were clamped (0 unless `policy` is [`NegativePolicy::Clamp`]).
/// `-0.0` is not negative.
pub fn check_radiance(path: impl AsRef<Path>, image: &mut Image, policy: NegativePolicy) -> Result<usize> {
    let path = path.as_ref();
    check_finite(path, image)?;
    let Some((x, y, channel, value)) = image.find_first(|v| v < 0.0) else {
        return Ok(0);
    };
    let count = image.data.iter().filter(|&&v| v < 0.0).count();
    match policy {
        NegativePolicy::Error => Err(Error::Negative { path: path.to_path_buf(), count, x, y, channel, value }),
        NegativePolicy::Clamp => {
            image.data.iter_mut().for_each(|v| *v = v.max(0.0));
            Ok(count)
        }
    }
}
