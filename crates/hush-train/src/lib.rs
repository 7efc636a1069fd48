//! The hush training loop, as a library: random crops of prepared samples, Adam at a constant learning
//! rate, a loss log, and self-describing checkpoints handed to the caller (this crate writes no files).
//!
//! * [`TrainConfig`]: network, features, loss, learning rate, steps, batch, crop, seed, checkpoints.
//! * [`TrainSample`]: an input/target pair already in the network's space;
//!   [`TrainSample::from_linear`] prepares one from linear images as OIDN's toolkit does.
//! * [`train`]: runs the loop, reports every step to an observer, returns [`Trained`].
//!
//! ```
//! use std::ops::ControlFlow;
//! use hush_dataset::Image;
//! use hush_net::{Features, UNetConfig, UNetKind};
//! use hush_train::{TrainConfig, TrainSample, train};
//!
//! // A 32×32 grey target and a noisy input, color only.
//! let target = Image::from_fn(32, 32, 3, |_, _, _| 0.5);
//! let input = Image::from_fn(32, 32, 3, |x, y, c| 0.5 + 0.2 * (((x * 7 + y * 13 + c) % 5) as f32 - 2.0) / 2.0);
//! let samples = vec![TrainSample { input, target }];
//!
//! let mut cfg = TrainConfig::thesis(Features::default());
//! cfg.net = UNetConfig { kind: UNetKind::Unet, in_channels: 3, out_channels: 3, width: 0.25 };
//! (cfg.steps, cfg.batch, cfg.crop, cfg.checkpoint_every) = (2, 1, 16, 0);
//! let trained = train(&cfg, &samples, &candle_core::Device::Cpu, None, |report| {
//!     println!("step {} loss {:.4}", report.row.step, report.row.loss);
//!     ControlFlow::Continue(())
//! })?;
//! assert_eq!(trained.log.len(), 2);
//! let (_net, info) = hush_net::load_model(&trained.weights, &candle_core::Device::Cpu)?;
//! assert_eq!(info.net, cfg.net);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod config;
mod error;
mod sample;
mod train;

pub use config::TrainConfig;
pub use error::{Result, TrainError};
pub use sample::TrainSample;
pub use train::{LossRow, Resume, StepReport, Trained, train};
