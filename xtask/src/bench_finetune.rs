//! `cargo xtask bench finetune`: what adaptation costs. On the demo's dataset (the Cornell box at 128²,
//! five views to train on, one held out), OIDN's `unet` is trained twice with the demo's settings, once from
//! OIDN's official weights (`--init oidn`, learning rate 1e-4) and once from random weights (learning rate
//! 1e-3, the defaults' from-scratch rate), for the same steps, in one run. Every 10 epochs a checkpoint is
//! evaluated on the held-out view (`hush eval`, its own auxiliary images), so the JSON holds the held-out PSNR
//! at 4 and 16 spp against wall-clock seconds of training for both starts, the steps per second, and official
//! OIDN's PSNR (the fine-tuned start's step 0). Written to `target/bench/finetune.json`.

use std::path::Path;
use std::process::Command;

use crate::demo::{DemoPaths, OFFICIAL_OIDN};
use crate::util::{Result, build_hush, ensure_vulkan, load_average, read_json, spawn, target_dir, write_json};

/// The held-out spp evaluated.
const SPP: [u64; 2] = [4, 16];

pub fn run(args: &[String]) -> Result<()> {
    let flags = crate::bench::flags(args, 4)?;
    ensure_vulkan()?;
    let hush = build_hush(flags.has("--release"))?;
    let steps: u32 = flags.number("--steps", 300)?;
    let paths = DemoPaths::new();
    if !paths.dataset.join("manifest.json").is_file() {
        crate::demo::render_dataset(&hush, &paths)?;
    }
    let dir = target_dir().join("bench/finetune");
    let _ = std::fs::remove_dir_all(&dir);
    let load_before = load_average();
    let mut runs = Vec::new();
    let mut official = serde_json::Value::Null;
    for (start, lr) in [("oidn", "1e-4"), ("scratch", "1e-3")] {
        let run = dir.join(start);
        let mut cmd = Command::new(&hush);
        cmd.arg("train").arg("--dataset").arg(&paths.dataset).arg("--out").arg(&run);
        if start == "oidn" {
            cmd.args(["--init", "oidn"]);
        } else {
            cmd.args(["--arch", "unet", "--width", "1"]);
        }
        cmd.args(["--features", "color,albedo,normal", "--spp", "4,16", "--batch", "4", "--crop", "64"]);
        cmd.args(["--loss", "mix", "--seed", "1", "--eval-every", "10", "--lr", lr, "--steps", &steps.to_string()]);
        spawn(&mut cmd)?;
        let summary = read_json(&run.join("summary.json"))?;
        let mut curve = Vec::new();
        for (epoch, step, seconds) in checkpoints(&run.join("metrics.csv"))? {
            let model = run.join(format!("checkpoints/epoch_{epoch:04}.safetensors"));
            let out = dir.join(format!("eval-{start}-{epoch:04}"));
            let mut eval = Command::new(&hush);
            eval.arg("eval").arg("--dataset").arg(&paths.dataset).arg("--model").arg(&model).arg("--out").arg(&out);
            eval.args(["--spp", "4,16", "--timing-runs", "1"]);
            if !official.is_null() {
                eval.arg("--no-official");
            }
            spawn(&mut eval)?;
            let rows = read_json(&out.join("summary.json"))?["rows"].clone();
            let psnr = |method: &str| -> serde_json::Value {
                SPP.iter()
                    .map(|&spp| {
                        let row = rows
                            .as_array()
                            .and_then(|r| r.iter().find(|r| r["method"] == method && r["spp"].as_u64() == Some(spp)));
                        (spp.to_string(), row.map_or(serde_json::Value::Null, |r| r["psnr"].clone()))
                    })
                    .collect::<serde_json::Map<_, _>>()
                    .into()
            };
            if official.is_null() {
                official = psnr(OFFICIAL_OIDN);
            }
            curve.push(serde_json::json!({
                "epoch": epoch, "step": step, "train_seconds": seconds,
                "held_out_psnr": psnr(&format!("checkpoints/epoch_{epoch:04}")),
            }));
        }
        runs.push(serde_json::json!({
            "start": start,
            "lr": lr,
            "steps": summary["steps"],
            "seconds": summary["seconds"],
            "steps_per_second": summary["steps_per_second"],
            "curve": curve,
        }));
    }
    let result = serde_json::json!({
        "benchmark": "finetune",
        "setting": "the demo's dataset (cbox 128², 5 training views, held-out view cbox_v005, noisy inputs with their \
                    own auxiliary images), OIDN's unet at full width, color+albedo+normal, spp 4 and 16, batch 4, \
                    64² crops, L_MIX; from OIDN's weights at lr 1e-4 and from random weights at lr 1e-3; PSNR after \
                    OIDN's tonemap on the held-out view against its 1024-path reference",
        "official_oidn_held_out_psnr": official,
        "runs": runs,
        "load_average": { "before": load_before, "after": load_average() },
    });
    let path = target_dir().join("bench/finetune.json");
    write_json(&path, &result)?;
    println!("{}", serde_json::to_string_pretty(&result).expect("serializes"));
    println!("written to {}", path.display());
    Ok(())
}

/// `(epoch, step, seconds)` of every epoch of `metrics.csv` with a test loss (those have a checkpoint).
fn checkpoints(metrics: &Path) -> Result<Vec<(u64, u64, f64)>> {
    let text = std::fs::read_to_string(metrics).map_err(|e| format!("reading {}: {e}", metrics.display()))?;
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap_or_default().split(',').collect();
    let col =
        |name: &str| header.iter().position(|h| *h == name).ok_or(format!("{}: no {name} column", metrics.display()));
    let (epoch, step, test, seconds) = (col("epoch")?, col("step")?, col("test_loss")?, col("seconds")?);
    let mut out = Vec::new();
    for line in lines {
        let f: Vec<&str> = line.split(',').collect();
        if f.get(test).is_some_and(|t| !t.is_empty()) {
            let num = |i: usize| f.get(i).and_then(|v| v.parse::<f64>().ok()).unwrap_or(f64::NAN);
            out.push((num(epoch) as u64, num(step) as u64, num(seconds)));
        }
    }
    Ok(out)
}
