//! hush's stages as a library: the dataset builder (scenes → views → noisy images, features and
//! references), training runs in a folder (options, defaults, resume, logs, checkpoints), the evaluation
//! against baselines with its report, and the procedural scenes and render statistics the command line
//! offers. The `hush` binary is a thin shell over this crate; another program can drive the same stages
//! without it. Progress and warnings reach an [`Observer`]; nothing here prints.
//!
//! Errors are `anyhow` chains whose messages name the file and the fix, as the command line shows them.
//!
//! A dataset of two views of the bundled Cornell box, a few training steps, and the evaluation (this needs a
//! Vulkan adapter: lavapipe on a machine without a GPU):
//!
//! ```
//! # fn main() -> anyhow::Result<()> {
//! use hush_pipeline::{DatasetPlan, EvalPlan, Quiet, TrainOptions, dataset, eval, train};
//!
//! let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
//! let dir = std::env::temp_dir().join(format!("hush-pipeline-doc-{}", std::process::id()));
//!
//! let mut plan = DatasetPlan::new(dir.join("dataset"), vec![root.join("data/scenes/cbox/scene.xml")]);
//! (plan.views, plan.size, plan.spp, plan.ref_spp, plan.aux_spp) = (2, Some(32), vec![4], 16, 4);
//! let gpu = hush_trace::GpuContext::new()?;
//! let renderer = hush_trace::Renderer::new(&gpu)?;
//! let built = dataset::build(&plan, &renderer, &Quiet)?;
//! assert_eq!((built.views, built.rendered), (2, 6));
//!
//! let options = TrainOptions {
//!     dataset: Some(plan.out.clone()),
//!     out: Some(dir.join("run")),
//!     steps: Some(3),
//!     crop: Some(16),
//!     width: Some(0.0625),
//!     ..Default::default()
//! };
//! let trained = train::run(options, &Quiet)?;
//! assert_eq!(trained.steps, 3);
//! assert!(trained.folder.model().is_file());
//!
//! let report = eval::evaluate(&EvalPlan::new(&plan.out, vec![trained.folder.model()], dir.join("eval")), &Quiet)?;
//! // Official OIDN comes beside every model.
//! assert_eq!(report.methods(), ["reference", "noisy", "run/model", "oidn-2.5.1 rt_hdr_alb_nrm"]);
//! assert!(dir.join("eval/report.md").is_file());
//! # std::fs::remove_dir_all(&dir)?;
//! # Ok(())
//! # }
//! ```

pub mod dataset;
mod device;
pub mod eval;
mod observer;
pub mod official;
mod probe;
pub mod procedural;
pub mod process;
pub mod scene;
pub mod shipped;
pub mod train;

pub use dataset::{BuildSummary, DatasetPlan};

/// The largest weight file hush reads (`--model`, `--init`, a checkpoint): 2 GiB, or `HUSH_MAX_WEIGHT_BYTES`
/// (bytes). OIDN's largest official network is 4 MB as TZA.
pub fn max_weight_bytes() -> hush_io::Limit {
    hush_io::Limit::from_env("HUSH_MAX_WEIGHT_BYTES", 2 << 30)
}

/// A weight file's bytes (a `.tza` or `.safetensors`), read up to [`max_weight_bytes`]; the error names the
/// file and what is wrong with it ("no such file", "is a directory", the limit).
pub fn read_weight_file(path: &std::path::Path) -> std::io::Result<Vec<u8>> {
    hush_io::read_limited(path, max_weight_bytes(), "weight file")
}
pub use device::{device, is_known as is_known_device};
pub use eval::{Denoiser, EvalPlan, blend_input, combine, keep_exact};
pub use observer::{Notes, Observer, Quiet, RenderProgress};
pub use probe::{MAX_ATTEMPTS, MIN_LIT_FRACTION, PROBE_SIZE, PROBE_SPP, lit_fraction, probe_size};
pub use scene::{RenderStats, ViewOverrides, load_scene};
pub use train::{RunConfig, RunFolder, TrainOptions, TrainOutcome};
