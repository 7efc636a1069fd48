//! `cargo xtask demo`: the whole pipeline on the bundled Cornell box.
//!
//! render a few perspectives (noisy at 4 and 16 spp, clean features, references) → fine-tune OIDN's
//! official weights on all but one perspective → denoise the held-out one with the fine-tuned model and with
//! OIDN's own weights → `target/demo/report.md`. Fails loudly unless the fine-tuned model beats both the
//! noisy input and official OIDN in PSNR at every spp.

use std::path::{Path, PathBuf};
use std::process::Command;

use crate::args::{Flags, Takes};
use crate::util::{Result, build_hush, ensure_vulkan, project_root, read_json, spawn, target_dir};

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

/// `hush train` of a narrow U-Net from scratch (width 0.25, lr 1e-3, batch 4, 64² crops; the demo's settings
/// before it fine-tuned OIDN's weights): what `cargo xtask train-check` trains and `bench train` measures.
pub fn train_command(hush: &Path, dataset: &Path, run: &Path, steps: u32) -> Command {
    let mut cmd = Command::new(hush);
    cmd.arg("train").arg("--dataset").arg(dataset).arg("--out").arg(run);
    cmd.args(["--features", "color,albedo,normal", "--spp", "4,16", "--batch", "4", "--crop", "64"]);
    cmd.args(["--width", "0.25", "--lr", "1e-3", "--loss", "mix", "--seed", "1", "--steps", &steps.to_string()]);
    cmd
}

/// The demo's fine-tuning: OIDN's official `rt_hdr_alb_nrm` weights (`--init oidn`: OIDN's `unet` at full
/// width) adapted to the dataset at `hush train`'s fine-tuning learning rate, 1e-4.
pub fn finetune_command(hush: &Path, dataset: &Path, run: &Path, steps: u32) -> Command {
    let mut cmd = Command::new(hush);
    cmd.arg("train").arg("--dataset").arg(dataset).arg("--out").arg(run).args(["--init", "oidn"]);
    cmd.args(["--features", "color,albedo,normal", "--spp", "4,16", "--batch", "4", "--crop", "64"]);
    cmd.args(["--loss", "mix", "--seed", "1", "--eval-every", "10", "--steps", &steps.to_string()]);
    cmd
}

/// Fine-tunes the demo model (300 steps, about 3 minutes on 2 cores) on the demo dataset.
pub fn train(hush: &Path, paths: &DemoPaths) -> Result<()> {
    spawn(&mut finetune_command(hush, &paths.dataset, &paths.run_dir, DEMO_STEPS))
}

/// The demo's fine-tuning steps.
pub const DEMO_STEPS: u32 = 300;

/// How `hush eval` names the official OIDN weights for color + albedo + normal in its reports.
pub const OFFICIAL_OIDN: &str = "oidn-2.5.1 rt_hdr_alb_nrm";

/// `hush eval` of one model on a dataset's test split into `out` (add baselines and options to it).
pub fn eval_command(hush: &Path, dataset: &Path, model: &Path, out: &Path) -> Command {
    let mut cmd = Command::new(hush);
    cmd.arg("eval").arg("--dataset").arg(dataset).arg("--model").arg(model).arg("--out").arg(out);
    cmd
}

/// The result rows of the `summary.json` that `hush eval` wrote into `dir`.
fn eval_rows(dir: &Path) -> Result<Vec<serde_json::Value>> {
    let path = dir.join("summary.json");
    let summary = read_json(&path)?;
    summary["rows"].as_array().cloned().ok_or_else(|| format!("{} has no rows", path.display()))
}

/// A noisy input's PSNR and the model's on the same view and spp, from `hush eval`'s rows.
pub struct NoisyAndModel {
    pub view: String,
    pub spp: u64,
    pub noisy: f64,
    /// `None` when the summary has no row of the model for this view and spp.
    pub model: Option<f64>,
    /// Official OIDN's ([`OFFICIAL_OIDN`]), `None` when the summary has none.
    pub oidn: Option<f64>,
}

/// Per noisy row of the `summary.json` that `hush eval --model model` wrote into `dir`: its PSNR and the
/// model's on the same view and spp. Only the model's own rows count (`hush eval` names them
/// `<run folder>/<file stem>`), not the reference's or a baseline's.
pub fn noisy_and_model_psnr(dir: &Path, model: &Path) -> Result<Vec<NoisyAndModel>> {
    let rows = eval_rows(dir)?;
    let name = |p: Option<&std::ffi::OsStr>| p.map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    let method = format!("{}/{}", name(model.parent().and_then(Path::file_name)), name(model.file_stem()));
    let psnr = |view: &str, spp: u64, method: &str| {
        rows.iter()
            .find(|r| r["view"] == view && r["spp"].as_u64() == Some(spp) && r["method"] == method)
            .and_then(|r| r["psnr"].as_f64())
    };
    Ok(rows
        .iter()
        .filter(|r| r["method"] == "noisy")
        .filter_map(|r| {
            let (view, spp) = (r["view"].as_str()?, r["spp"].as_u64()?);
            let noisy = r["psnr"].as_f64()?;
            let (model, oidn) = (psnr(view, spp, &method), psnr(view, spp, OFFICIAL_OIDN));
            Some(NoisyAndModel { view: view.into(), spp, noisy, model, oidn })
        })
        .collect())
}

pub fn run(args: &[String]) -> Result<()> {
    let known = [("--release", Takes::Nothing), ("--resume", Takes::Nothing)];
    let flags = Flags::parse(args, &known, 0, "cargo xtask demo [--release] [--resume]")?;
    ensure_vulkan()?;
    let hush = build_hush(flags.has("--release"))?;
    let paths = DemoPaths::new();
    let dir = &paths.dir;
    // Each demo starts from scratch, so that output of an older build never mixes in;
    // `--resume` keeps what an interrupted demo already rendered and trained.
    if !flags.has("--resume") && dir.exists() {
        std::fs::remove_dir_all(dir).map_err(|e| format!("cannot clear {}: {e}", dir.display()))?;
    }
    render_dataset(&hush, &paths)?;
    train(&hush, &paths)?;
    spawn(&mut eval_command(&hush, &paths.dataset, &paths.model(), dir))?;

    let mut failures = Vec::new();
    let mut checked = 0;
    for NoisyAndModel { view, spp, noisy: n, model, oidn } in noisy_and_model_psnr(dir, &paths.model())? {
        let (Some(d), Some(o)) = (model, oidn) else {
            failures.push(format!("{view} at {spp} spp: no result of the model or of official OIDN"));
            continue;
        };
        checked += 1;
        println!(
            "{view} at {spp} spp: noisy {n:.2} dB, official OIDN {o:.2} dB, fine-tuned {d:.2} dB ({:+.2} dB over OIDN)",
            d - o
        );
        if d <= n {
            failures.push(format!("{view} at {spp} spp: denoised PSNR {d:.2} dB does not beat noisy {n:.2} dB"));
        }
        if d <= o {
            failures
                .push(format!("{view} at {spp} spp: the fine-tuned {d:.2} dB does not beat official OIDN {o:.2} dB"));
        }
    }
    if checked == 0 {
        failures.push("the report compares nothing".into());
    }
    println!("report: {}", dir.join("report.md").display());
    if !failures.is_empty() {
        return Err(format!("the demo's model fell short:\n  {}", failures.join("\n  ")));
    }
    Ok(())
}
