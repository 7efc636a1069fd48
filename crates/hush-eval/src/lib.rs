//! Metrics (PSNR, SSIM, MS-SSIM, MAE, MSE after Open Image Denoise's tonemap; relMSE on HDR), timing, error
//! against run time, pictures and reports for hush denoisers.
//!
//! Conventions: every metric takes `(test, reference)`. Both images are tonemapped with the exposure
//! computed from the **reference** ([`exposure_of`]: OIDN's autoexposure), then OIDN's filmic curve and sRGB
//! ([`tonemap`]); PSNR, SSIM, MS-SSIM, MAE and MSE compare those [0, 1] images, relMSE the linear ones. SSIM is
//! `hush_net::loss::ssim`, the same code as the training loss. See [`CONVENTIONS`].
//!
//! ```
//! # fn main() -> hush_eval::Result<()> {
//! use hush_dataset::Image;
//! use hush_eval::{compare, Report, Row};
//!
//! let reference = Image::from_fn(16, 16, 3, |x, y, _| 0.1 + 0.01 * (x + y) as f32);
//! let mut noisy = reference.clone();
//! noisy.pixel_mut(3, 4)[0] += 0.5;
//! let m = compare(&noisy, &reference)?;
//! assert!(m.psnr > 30.0 && m.ssim < 1.0 && m.ms_ssim.is_none());
//! assert!(compare(&reference, &reference)?.psnr.is_infinite());
//!
//! let report = Report { rows: vec![Row::new("cbox_v0", "noisy", 4, &m)], ..Report::default() };
//! assert!(report.to_markdown().contains("| noisy | 4 |"));
//! # Ok(())
//! # }
//! ```

pub mod doc;
mod error;
pub mod external;
pub mod flip;
pub mod guided;
pub mod html;
mod metrics;
#[cfg(feature = "oidn")]
pub mod oidn_native;
pub mod pictures;
mod plot;
mod report;
pub mod sweep;
mod timing;
mod tonemap;
pub mod tradeoff;
pub mod viewer;

pub use error::{Error, Result};
pub use metrics::{
    MS_SSIM_MIN_SIDE, Metrics, color_shift, compare, mae, ms_ssim_tonemapped, mse, psnr, psnr_of_mse, rel_mse, ssim,
    ssim_tonemapped,
};
pub use plot::{error_vs_time_chart, metric_axis, plot_error_vs_time, series_color};
pub use report::{
    CONVENTIONS, Figure, FigureImage, FigureKind, NOISY, REFERENCE, Report, Row, SCHEMA, Skipped, Table, shown_path,
};
pub use timing::{Timing, time_median};
pub use tonemap::{exposure_of, filmic, tonemap};
pub use viewer::{Viewer, ViewerImage};
