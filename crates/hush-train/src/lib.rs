//! The hush training loop, as a library: random crops of prepared samples, the thesis's optimizers and
//! learning-rate schedules, per-epoch test loss, and resumable checkpoints handed to the caller as bytes
//! (this crate writes no files).
//!
//! * [`TrainConfig`]: network, features, loss, optimizer, learning rate and schedule, steps, batch, crop,
//!   augmentation, seed.
//! * [`Optimizer`]: Adam/AdamW and SGD with momentum whose state can be saved and restored exactly.
//! * [`Schedule`]: the learning rate per epoch (thesis §4.4: constant, lambda, exponential, cosine, SGDR,
//!   and OIDN's one-cycle).
//! * [`TrainSample`]: an input/target pair already in the network's space;
//!   [`TrainSample::from_linear`] prepares one from linear images as OIDN's toolkit does.
//! * [`train`]: runs the loop from random weights, trained ones ([`Start::Init`], fine-tuning) or a
//!   checkpoint, reports every step to an observer, returns [`Trained`];
//!   [`read_train_state`] reads where a checkpoint stands.
//! * [`encode_samples`] / [`decode_samples`]: prepared samples as f16 bytes under a key with a checksum, for
//!   an on-disk cache that a change of data or settings invalidates.
//! * [`plot_losses`]: an SVG chart of the training and test loss curves.
//!
//! ```
//! use std::ops::ControlFlow;
//! use hush_dataset::Image;
//! use hush_net::{InputFeatures, UNetConfig, UNetKind};
//! use hush_train::{Start, TrainConfig, TrainSample, train};
//!
//! // A 32×32 grey target and a noisy input, color only.
//! let target = Image::from_fn(32, 32, 3, |_, _, _| 0.5);
//! let input = Image::from_fn(32, 32, 3, |x, y, c| 0.5 + 0.2 * (((x * 7 + y * 13 + c) % 5) as f32 - 2.0) / 2.0);
//! let samples = vec![TrainSample { input, target }];
//!
//! let mut cfg = TrainConfig::thesis(InputFeatures::default());
//! cfg.net = UNetConfig::new(UNetKind::Unet, 3, 0.25).into();
//! (cfg.steps, cfg.batch, cfg.crop) = (2, 1, 16);
//! let trained = train(&cfg, &samples, &[], &candle_core::Device::Cpu, Start::Fresh, |report| {
//!     println!("step {} loss {:.4}", report.row.step, report.row.loss);
//!     ControlFlow::Continue(())
//! })?;
//! assert_eq!(trained.log.len(), 2);
//! let (_net, info) = hush_net::load_model(&trained.weights, &candle_core::Device::Cpu)?;
//! assert_eq!(info.net, cfg.net);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod cache;
mod checkpoint;
mod config;
mod error;
mod log;
mod optim;
mod plot;
mod sample;
mod schedule;
mod train;

pub use cache::{decode_samples, encode_samples, round_trip};
pub use checkpoint::{STATE_KEY, TrainState, read_train_state};
pub use config::{InitRecord, TrainConfig};
pub use error::{Result, TrainError};
pub use log::{LOSS_COLUMNS, METRICS_COLUMNS, loss_csv, metrics_csv, parse_loss_csv, parse_metrics_csv};
pub use optim::{Optimizer, OptimizerConfig};
pub use plot::plot_losses;
pub use sample::{Augment, Crop, PREPARATION_VERSION, TrainSample};
pub use schedule::Schedule;
pub use train::{EpochRow, LossRow, Start, StepReport, Trained, train};
