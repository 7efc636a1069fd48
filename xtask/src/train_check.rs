//! `cargo xtask train-check`: the held-out acceptance of training on more than one scene.
//!
//! Renders a small dataset of the bundled Cornell box and Veach's MIS scene (each scene's last views held
//! out), trains a narrow U-Net for a fixed budget on the other views, evaluates the held-out views at 4 spp
//! and fails unless, for each scene, the model's mean PSNR beats the noisy input's by at least
//! [`MIN_GAIN_DB`]. The numbers go to `target/train-check/summary.json`.

use std::collections::BTreeMap;
use std::path::Path;
use std::process::Command;

use crate::args::{Flags, Takes};
use crate::demo::{eval_command, noisy_and_model_psnr, train_command};
use crate::util::{
    Result, build_hush, ensure_vulkan, load_average, project_root, read_json, spawn, target_dir, write_json,
};

/// The scenes, as paths below the repository root.
const SCENES: [&str; 2] = ["data/scenes/cbox/scene.xml", "data/scenes/veach-mis/scene.xml"];
/// The required PSNR gain over the noisy input at [`SPP`], per scene.
pub const MIN_GAIN_DB: f64 = 5.0;
/// The noisy input's samples per pixel that is checked.
const SPP: u64 = 4;
/// The training budget, in steps of `demo::train_command` (from scratch: batch 4, 64² crops, width 0.25).
const STEPS: u32 = 2000;

pub fn run(args: &[String]) -> Result<()> {
    let known = [("--release", Takes::Nothing), ("--resume", Takes::Nothing), ("--steps", Takes::Number)];
    let flags = Flags::parse(args, &known, 0, "cargo xtask train-check [--release] [--resume] [--steps N]")?;
    let steps = flags.number("--steps", STEPS)?;
    ensure_vulkan()?;
    let hush = build_hush(flags.has("--release"))?;
    let dir = target_dir().join("train-check");
    // A fresh start unless `--resume` (the dataset and the training both continue where they stopped).
    if !flags.has("--resume") && dir.exists() {
        std::fs::remove_dir_all(&dir).map_err(|e| format!("cannot clear {}: {e}", dir.display()))?;
    }
    let (dataset, run_dir, eval_dir) = (dir.join("dataset"), dir.join("run"), dir.join("eval"));
    let load_before = load_average();
    let root = project_root();
    let start = std::time::Instant::now();
    spawn(
        Command::new(&hush)
            .arg("dataset")
            .args(SCENES.iter().map(|s| root.join(s)))
            .arg("--out")
            .arg(&dataset)
            .args(["--split-views", "--views", "6", "--test-views", "2", "--spp", "4,16", "--ref-spp", "256"])
            .args(["--aux-spp", "32", "--size", "128", "--seed", "1"]),
    )?;
    let dataset_seconds = start.elapsed().as_secs_f64();
    let start = std::time::Instant::now();
    spawn(&mut train_command(&hush, &dataset, &run_dir, steps))?;
    let train_seconds = start.elapsed().as_secs_f64();
    let model = run_dir.join("model.safetensors");
    spawn(eval_command(&hush, &dataset, &model, &eval_dir).args(["--spp", &SPP.to_string(), "--timing-runs", "1"]))?;
    let (scenes, failures) = per_scene_gains(&eval_dir, &model)?;
    let summary = serde_json::json!({
        "check": format!("per scene, mean PSNR of the model on held-out views at {SPP} spp ≥ noisy + {MIN_GAIN_DB} dB"),
        "steps": steps,
        "scenes": scenes,
        "dataset_seconds": dataset_seconds,
        "train_seconds": train_seconds,
        "train_summary": read_json(&run_dir.join("summary.json")).ok(),
        "load_average_before": load_before,
        "load_average_after": load_average(),
        "passed": failures.is_empty(),
    });
    write_json(&dir.join("summary.json"), &summary)?;
    println!("written to {}", dir.join("summary.json").display());
    if !failures.is_empty() {
        return Err(format!("the held-out gain is below {MIN_GAIN_DB} dB:\n  {}", failures.join("\n  ")));
    }
    Ok(())
}

/// A view's PSNR of the noisy input and of the model.
type PsnrPair = (Option<f64>, Option<f64>);

/// Per scene (the view names' part before `_v`): the held-out views' PSNR of the noisy input and the model
/// at [`SPP`], their means and the gain; and a failure line per scene below [`MIN_GAIN_DB`].
fn per_scene_gains(eval_dir: &Path, model: &Path) -> Result<(serde_json::Value, Vec<String>)> {
    let mut by_scene: BTreeMap<String, BTreeMap<String, PsnrPair>> = BTreeMap::new();
    for r in noisy_and_model_psnr(eval_dir, model)?.into_iter().filter(|r| r.spp == SPP) {
        let scene = r.view.rsplit_once("_v").map_or(r.view.as_str(), |(s, _)| s).to_string();
        by_scene.entry(scene).or_default().insert(r.view, (Some(r.noisy), r.model));
    }
    let mut failures = Vec::new();
    let mut out = serde_json::Map::new();
    for want in SCENES {
        let name = Path::new(want).parent().and_then(|p| p.file_name()).map(|n| n.to_string_lossy().into_owned());
        let name = name.unwrap_or_default();
        let Some(views) = by_scene.get(&name) else {
            failures.push(format!("{name}: no held-out view was evaluated"));
            continue;
        };
        let mut pairs = Vec::new();
        for (view, &(noisy, model)) in views {
            match (noisy, model) {
                (Some(n), Some(m)) => {
                    println!("{view} at {SPP} spp: noisy {n:.2} dB → model {m:.2} dB ({:+.2} dB)", m - n);
                    pairs.push(serde_json::json!({"view": view, "noisy_psnr": n, "model_psnr": m}));
                }
                _ => failures.push(format!("{view} at {SPP} spp: the report lacks the noisy or the model result")),
            }
        }
        let mean = |key: &str| pairs.iter().filter_map(|p| p[key].as_f64()).sum::<f64>() / pairs.len().max(1) as f64;
        let (noisy, model) = (mean("noisy_psnr"), mean("model_psnr"));
        let gain = model - noisy;
        println!(
            "{name}: {} held-out views, noisy {noisy:.2} dB → model {model:.2} dB, gain {gain:+.2} dB",
            pairs.len()
        );
        if pairs.is_empty() || gain < MIN_GAIN_DB {
            failures.push(format!("{name}: gain {gain:+.2} dB (noisy {noisy:.2} → model {model:.2})"));
        }
        out.insert(
            name,
            serde_json::json!({"views": pairs, "noisy_psnr": noisy, "model_psnr": model, "gain_db": gain}),
        );
    }
    Ok((serde_json::Value::Object(out), failures))
}
