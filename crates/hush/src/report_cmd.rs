//! `hush sweep-report`: the reports of `cargo xtask sweep`, from the plan xtask writes (see
//! `hush_eval::sweep::Plan`) and the run folders it names.

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::Args;

#[derive(Args, Debug)]
pub struct SweepReportArgs {
    /// The plan (JSON) xtask wrote: the scale, each sweep's runs and folders, and the folder of the report on
    /// every sweep.
    #[arg(long)]
    pub plan: PathBuf,
}

pub fn run(args: SweepReportArgs) -> Result<()> {
    let plan = hush_eval::sweep::read_plan(&args.plan)?;
    let written = hush_eval::sweep::write_reports(&plan)
        .with_context(|| format!("writing the reports of the plan {}", args.plan.display()))?;
    for report in written {
        println!("report: {}", report.display());
    }
    Ok(())
}
