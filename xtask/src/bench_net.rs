//! `cargo xtask bench net` and `cargo xtask bench train`.
//!
//! `net`: inference at 512² with 9 input channels (color, albedo, normal) through OIDN's `unet`, hush
//! (Candle, randomly initialized weights: dense convolutions cost the same whatever the values) against
//! official OIDN 2.5.1 (`pyoidn.denoise`, quality "high" = the same `unet`, `clean_aux` so that neither
//! prefilters the features), warm medians in one run; a training step (batch 4, 128², 12 channels:
//! color, diffuse, specular, normal) with its achieved GFLOP/s against Candle's f32 GEMM rate measured in
//! the same run; peak memory of each process. hush's runs repeat for 1 and 2 threads (RAYON_NUM_THREADS)
//! so that the default thread count can be chosen from the numbers.
//!
//! `train`: steps per second and the loader's share of `hush train` in its default configuration (the
//! narrow U-Net from scratch, `demo::train_command`) on a small Cornell box dataset, rendered first when missing.

use std::path::Path;
use std::process::Command;

use crate::baselines;
use crate::bench::flags;
use crate::util::{Result, build_hush, ensure_vulkan, load_average, output, project_root, spawn, target_dir};
use crate::util::{read_json, write_json};

fn hush_json(hush: &Path, threads: Option<usize>, args: &[&str]) -> Result<serde_json::Value> {
    let mut cmd = Command::new(hush);
    cmd.arg("bench").args(args);
    if let Some(t) = threads {
        cmd.env("RAYON_NUM_THREADS", t.to_string());
    }
    let text = output(&mut cmd)?;
    serde_json::from_str(&text).map_err(|e| format!("`hush bench {}` printed no JSON: {e}", args.join(" ")))
}

/// Times `pyoidn.denoise` on a synthetic 512² image with albedo and normal: median of `runs` after a warm-up.
const OIDN_SCRIPT: &str = r#"
import json, resource, sys, time
import numpy as np
import pyoidn
size, runs = int(sys.argv[1]), int(sys.argv[2])
rng = np.random.default_rng(1)
color = rng.random((size, size, 3), dtype=np.float32)
albedo = rng.random((size, size, 3), dtype=np.float32)
normal = rng.random((size, size, 3), dtype=np.float32) * 2 - 1
pyoidn.denoise(color, albedo, normal, hdr=True, clean_aux=True, quality="high")
times = []
for _ in range(runs):
    t = time.perf_counter()
    pyoidn.denoise(color, albedo, normal, hdr=True, clean_aux=True, quality="high")
    times.append(time.perf_counter() - t)
times.sort()
print(json.dumps({"what": "inference", "implementation": "pyoidn " + getattr(pyoidn, "__version__", "2.5.1"),
                  "size": size, "seconds": times[len(times) // 2], "runs_seconds": times,
                  "peak_rss_bytes": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024}))
"#;

fn oidn(size: usize, runs: usize) -> serde_json::Value {
    let python = baselines::venv_python();
    if !python.is_file() {
        return serde_json::json!({ "skipped": format!("{} not found", python.display()), "install": baselines::SETUP });
    }
    let result = output(Command::new(&python).args(["-c", OIDN_SCRIPT, &size.to_string(), &runs.to_string()]))
        .and_then(|text| {
            serde_json::from_str(text.trim()).map_err(|e| format!("the OIDN timing printed no JSON: {e}"))
        });
    result.unwrap_or_else(|e| serde_json::json!({ "skipped": e, "install": baselines::SETUP }))
}

fn ratio(a: &serde_json::Value, b: &serde_json::Value) -> serde_json::Value {
    match (a.as_f64(), b.as_f64()) {
        (Some(a), Some(b)) if b > 0.0 => serde_json::json!(a / b),
        _ => serde_json::Value::Null,
    }
}

/// The smaller of two `seconds` results, with its thread count.
fn fastest(results: &[(usize, serde_json::Value)]) -> (usize, serde_json::Value) {
    results
        .iter()
        .min_by(|a, b| {
            a.1["seconds"]
                .as_f64()
                .unwrap_or(f64::INFINITY)
                .total_cmp(&b.1["seconds"].as_f64().unwrap_or(f64::INFINITY))
        })
        .cloned()
        .expect("at least one thread count")
}

pub fn net(args: &[String]) -> Result<()> {
    let hush = build_hush(flags(args, 2)?.has("--release"))?;
    let runs = "3";
    let load_before = load_average();
    let thread_counts = [1usize, 2];
    let mut inference = Vec::new();
    let mut train = Vec::new();
    let mut gemm = Vec::new();
    for &t in &thread_counts {
        inference.push((
            t,
            hush_json(&hush, Some(t), &["inference", "--size", "512", "--features", "alb,nrm", "--runs", runs])?,
        ));
        train.push((
            t,
            hush_json(
                &hush,
                Some(t),
                &["train-step", "--size", "128", "--batch", "4", "--features", "diff,spec,nrm", "--runs", runs],
            )?,
        ));
        gemm.push((t, hush_json(&hush, Some(t), &["gemm", "--size", "1024", "--runs", "5"])?));
    }
    let oidn = oidn(512, 5);
    let (best_threads, best_inference) = fastest(&inference);
    let (train_threads, best_train) = fastest(&train);
    let gemm_at = |t: usize| gemm.iter().find(|g| g.0 == t).map(|g| g.1.clone()).unwrap_or_default();
    let per_threads = |v: &[(usize, serde_json::Value)]| {
        serde_json::Value::Object(v.iter().map(|(t, j)| (t.to_string(), j.clone())).collect())
    };
    let result = serde_json::json!({
        "benchmark": "net",
        "inference": {
            "setting": "512x512, 9 channels (color, albedo, normal), unet at full width, whole inference path",
            "hush_by_threads": per_threads(&inference),
            "hush_best_threads": best_threads,
            "oidn": oidn,
            "hush_over_oidn_seconds": ratio(&best_inference["seconds"], &oidn["seconds"]),
            "goal": "hush_over_oidn_seconds <= 1.0",
        },
        "train_step": {
            "setting": "batch 4, 128x128, 12 channels (color, diffuse, specular, normal), unet, L_MIX, Adam",
            "hush_by_threads": per_threads(&train),
            "gemm_by_threads": per_threads(&gemm),
            "best_threads": train_threads,
            "gflops_over_gemm_gflops": ratio(&best_train["gflops"], &gemm_at(train_threads)["gflops"]),
            "goal": "gflops_over_gemm_gflops >= 0.7",
        },
        "load_average": { "before": load_before, "after": load_average() },
    });
    let path = target_dir().join("bench/net.json");
    write_json(&path, &result)?;
    println!("{}", serde_json::to_string_pretty(&result).expect("serializes"));
    println!("written to {}", path.display());
    Ok(())
}

/// `demo::train_command`'s from-scratch settings, `--steps` of them (default 60).
pub fn train(args: &[String]) -> Result<()> {
    let flags = flags(args, 3)?;
    ensure_vulkan()?;
    let hush = build_hush(flags.has("--release"))?;
    let steps: u32 = flags.number("--steps", 60)?;
    let dir = target_dir().join("bench");
    let dataset = dir.join("train-dataset");
    if !dataset.join("manifest.json").is_file() {
        spawn(
            Command::new(&hush)
                .arg("dataset")
                .arg(project_root().join("data/scenes/cbox/scene.xml"))
                .arg("--out")
                .arg(&dataset)
                .args(["--views", "3", "--test-views", "1", "--spp", "4,16", "--ref-spp", "64"])
                .args(["--aux-spp", "16", "--size", "128", "--seed", "1"]),
        )?;
    }
    let run = dir.join("train-run");
    let _ = std::fs::remove_dir_all(&run);
    let load_before = load_average();
    spawn(&mut crate::demo::train_command(&hush, &dataset, &run, steps))?;
    let summary = read_json(&run.join("summary.json"))?;
    let result = serde_json::json!({
        "benchmark": "train",
        "setting": "a narrow U-Net from scratch: cbox 128² dataset, features color+albedo+normal, spp 4 and 16, batch 4, 64² crops, \
                    unet width 0.25, L_MIX, Adam 1e-3",
        "steps": summary["steps"],
        "seconds": summary["seconds"],
        "steps_per_second": summary["steps_per_second"],
        "loader_share": summary["loader_share"],
        "load_seconds": summary["load_seconds"],
        "threads": summary["threads"],
        "load_average": { "before": load_before, "after": load_average() },
    });
    let path = dir.join("train.json");
    write_json(&path, &result)?;
    println!("{}", serde_json::to_string_pretty(&result).expect("serializes"));
    println!("written to {}", path.display());
    Ok(())
}
