//! `hush eval`: models and baselines against the noisy input on a dataset's test split (hush-pipeline's
//! `eval`), written as a report.

use anyhow::Result;
use hush_eval::Report;
use hush_pipeline::eval::evaluate;

use crate::cli::EvalArgs;
use crate::progress::Bars;

pub fn run(args: EvalArgs) -> Result<()> {
    let plan = args.plan();
    evaluate(&plan, &Bars::default())?;
    eprintln!("report: {}", plan.out.join(Report::HTML_FILE).display());
    eprintln!("report: {}", plan.out.join(Report::MARKDOWN_FILE).display());
    Ok(())
}
