//! `cargo xtask demo`: the whole pipeline on the bundled Cornell box.
//!
//! render a few perspectives (noisy at 4 and 16 spp, clean features, references) → train a
//! narrow U-Net on all but one perspective → denoise the held-out one → `target/demo/report.md`.
//! Fails loudly unless the denoised image beats the noisy one in PSNR at every spp.

use std::path::{Path, PathBuf};
use std::process::Command;

use crate::util::{Result, build_hush, ensure_vulkan, project_root, read_json, release, spawn, target_dir};

/// Where the demo writes: `target/demo/` with `dataset/`, `run/` and the report.
pub struct DemoPaths {
    pub dir: PathBuf,
    pub dataset: PathBuf,
    pub run_dir: PathBuf,
}

impl DemoPaths {
    pub fn new() -> DemoPaths {
        let dir = target_dir().join("demo");
        DemoPaths { dataset: dir.join("dataset"), run_dir: dir.join("run"), dir }
    }

    /// The trained model.
    pub fn model(&self) -> PathBuf {
        self.run_dir.join("model.safetensors")
    }
}

/// Renders the demo dataset (resuming what is already rendered).
pub fn render_dataset(hush: &Path, paths: &DemoPaths) -> Result<()> {
    let scene = project_root().join("data/scenes/cbox/scene.xml");
    spawn(
        Command::new(hush)
            .arg("dataset")
            .arg(&scene)
            .arg("--out")
            .arg(&paths.dataset)
            .args(["--views", "6", "--test-views", "1", "--spp", "4,16", "--ref-spp", "256"])
            .args(["--aux-spp", "32", "--size", "128", "--seed", "1"]),
    )
}

/// `hush train` with the demo's settings; `cargo xtask bench train` measures the same.
pub fn train_command(hush: &Path, dataset: &Path, run: &Path, steps: u32) -> Command {
    let mut cmd = Command::new(hush);
    cmd.arg("train").arg("--dataset").arg(dataset).arg("--out").arg(run);
    cmd.args(["--features", "color,albedo,normal", "--spp", "4,16", "--batch", "4", "--crop", "64"]);
    cmd.args(["--width", "0.25", "--lr", "1e-3", "--loss", "mix", "--seed", "1", "--steps", &steps.to_string()]);
    cmd
}

/// Trains the demo model (1000 steps) on the demo dataset.
pub fn train(hush: &Path, paths: &DemoPaths) -> Result<()> {
    spawn(&mut train_command(hush, &paths.dataset, &paths.run_dir, 1000))
}

/// `hush eval` of one model on a dataset's test split into `out` (add baselines and options to it).
pub fn eval_command(hush: &Path, dataset: &Path, model: &Path, out: &Path) -> Command {
    let mut cmd = Command::new(hush);
    cmd.arg("eval").arg("--dataset").arg(dataset).arg("--model").arg(model).arg("--out").arg(out);
    cmd
}

/// The result rows of the `summary.json` that `hush eval` wrote into `dir`.
pub fn eval_rows(dir: &Path) -> Result<Vec<serde_json::Value>> {
    let path = dir.join("summary.json");
    let summary = read_json(&path)?;
    summary["rows"].as_array().cloned().ok_or_else(|| format!("{} has no rows", path.display()))
}

pub fn run(args: &[String]) -> Result<()> {
    ensure_vulkan()?;
    let hush = build_hush(release(args))?;
    let paths = DemoPaths::new();
    let dir = &paths.dir;
    // Each demo starts from scratch, so that output of an older build never mixes in;
    // `--resume` keeps what an interrupted demo already rendered and trained.
    if !args.iter().any(|a| a == "--resume") && dir.exists() {
        std::fs::remove_dir_all(dir).map_err(|e| format!("cannot clear {}: {e}", dir.display()))?;
    }
    render_dataset(&hush, &paths)?;
    train(&hush, &paths)?;
    spawn(&mut eval_command(&hush, &paths.dataset, &paths.model(), dir))?;

    let rows = eval_rows(dir)?;
    let psnr = |view: &str, spp: u64, noisy: bool| {
        rows.iter()
            .find(|r| r["view"] == view && r["spp"].as_u64() == Some(spp) && (r["method"] == "noisy") == noisy)
            .and_then(|r| r["psnr"].as_f64())
    };
    let mut failures = Vec::new();
    let mut checked = 0;
    for row in rows.iter().filter(|r| r["method"] == "noisy") {
        let (view, spp) = (row["view"].as_str().unwrap_or_default(), row["spp"].as_u64().unwrap_or_default());
        let (Some(n), Some(d)) = (psnr(view, spp, true), psnr(view, spp, false)) else {
            failures.push(format!("{view} at {spp} spp: no denoised result"));
            continue;
        };
        checked += 1;
        println!("{view} at {spp} spp: noisy {n:.2} dB → denoised {d:.2} dB");
        if d <= n {
            failures.push(format!("{view} at {spp} spp: denoised PSNR {d:.2} dB does not beat noisy {n:.2} dB"));
        }
    }
    if checked == 0 {
        failures.push("the report compares nothing".into());
    }
    println!("report: {}", dir.join("report.md").display());
    if !failures.is_empty() {
        return Err(format!("the denoiser did not beat the noisy input:\n  {}", failures.join("\n  ")));
    }
    Ok(())
}
