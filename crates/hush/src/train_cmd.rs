//! `hush train`: a training run in a folder (hush-pipeline's `train`), with a progress bar.

use anyhow::Result;
use hush_pipeline::TrainOptions;

use crate::progress::Bars;

pub fn run(options: TrainOptions) -> Result<()> {
    let trained = hush_pipeline::train::run(options, &Bars::default())?;
    let test_note = match trained.best {
        Some((epoch, loss)) => format!("; best test loss {loss:.4} at epoch {epoch}"),
        None => String::new(),
    };
    eprintln!(
        "trained {} steps: loss {:.4} → {:.4}{test_note}; {:.2} steps/s, the loader's share {:.1}%; model {}",
        trained.config.train.steps,
        trained.first_loss,
        trained.final_loss,
        trained.steps as f64 / trained.seconds.max(1e-9),
        100.0 * trained.loader_share,
        trained.folder.model().display()
    );
    Ok(())
}
