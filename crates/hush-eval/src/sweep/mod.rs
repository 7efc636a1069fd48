//! The reports of the thesis's hyperparameter sweeps (`cargo xtask sweep`, run by `hush sweep-report`): what
//! each run left behind ([`results`]), the thesis's findings decided from it ([`claims`]) and
//! `report.md`/`report.html` with their figures ([`report`]).
//!
//! xtask runs the sweeps and describes them in a [`Plan`] (JSON): the scale, and per sweep its runs with
//! their `hush train` flags and folders. Everything is read from the run folders: `train/metrics.csv`,
//! `eval/summary.json` and `done.json` (a run is complete when it exists).

pub mod claims;
mod findings;
pub mod report;
pub mod results;

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::{Error, Result};
use results::RunResult;

/// The sweeps to report on, as xtask writes them.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Plan {
    pub scale: PlanScale,
    pub sweeps: Vec<PlanSweep>,
    /// The folder of the report on every sweep of the plan (`all`); `None` for one sweep.
    #[serde(default)]
    pub all: Option<PathBuf>,
}

/// A scale of the sweeps (`data/sweeps/scales.toml`).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PlanScale {
    pub name: String,
    /// The scene files or folders of `hush dataset`.
    pub scenes: Vec<String>,
    /// The other arguments of `hush dataset`.
    pub dataset: Vec<String>,
    /// The `hush train` arguments every run of the scale gets.
    pub train: Vec<String>,
    pub seeds: Vec<u64>,
}

/// One sweep (`data/sweeps/<name>.toml`) and where its report goes.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PlanSweep {
    pub name: String,
    pub description: String,
    /// The report's folder; a run's images are linked relative to it.
    pub dir: PathBuf,
    pub runs: Vec<PlanRun>,
}

/// One `hush train` + `hush eval` of a sweep.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PlanRun {
    pub sweep: String,
    /// The variants' names joined by `-`, then `-s<seed>` with several seeds.
    pub name: String,
    /// The name without the seed: runs that differ only in their seed share it.
    pub group: String,
    pub seed: u64,
    /// `hush train` flags and their values (without dataset, out and seed), in a fixed order.
    pub train: Vec<(String, String)>,
    /// The run's folder (`train/`, `eval/`, `done.json`).
    pub dir: PathBuf,
}

/// `--key value` for each flag.
pub fn flags(pairs: &[(String, String)]) -> Vec<String> {
    pairs.iter().flat_map(|(k, v)| [format!("--{k}"), v.clone()]).collect()
}

/// Reads a plan written by xtask.
pub fn read_plan(path: &Path) -> Result<Plan> {
    let text = std::fs::read_to_string(path).map_err(|source| Error::File {
        path: path.to_path_buf(),
        action: "read the sweep plan",
        source,
    })?;
    serde_json::from_str(&text).map_err(|source| Error::ReadJson { path: path.to_path_buf(), source })
}

/// Writes the report of every sweep of `plan` into its folder, and with several the `all` report; returns
/// the `report.md` files written.
pub fn write_reports(plan: &Plan) -> Result<Vec<PathBuf>> {
    let mut written = Vec::new();
    let mut every_claim = Vec::new();
    let mut every_result = Vec::new();
    for sweep in &plan.sweeps {
        let results = sweep.runs.iter().map(RunResult::load).collect::<Result<Vec<_>>>()?;
        let claims = report::write(sweep, &plan.scale, &results, &sweep.dir)?;
        written.push(sweep.dir.join(crate::Report::MARKDOWN_FILE));
        every_claim.push((sweep.name.clone(), claims));
        every_result.extend(results);
    }
    if let Some(dir) = &plan.all {
        report::write_all(&plan.scale, &every_claim, &every_result, dir)?;
        written.push(dir.join(crate::Report::MARKDOWN_FILE));
    }
    Ok(written)
}
