//! `cargo xtask bench net` and `cargo xtask bench train`.
//!
//! `net`: inference of OIDN's three CPU models (`unet_small`, `unet`, `unet_large`) at 512² and
//! 1920×1080 with color, albedo and normal, hush against OIDN 2.5.1 on the same official TZA weights and
//! the same PFM inputs: warm figures (hush's `Denoiser` kept between executions, `oidnDenoise -n` one
//! filter executed repeatedly) and whole processes at 960² (`hush denoise --model` against `oidnDenoise
//! -w`), peak memory of each; every row says its setting and no row compares two different models. Then a
//! training step (batch 4, 128², 12 channels: color, diffuse, specular, normal) with its achieved GFLOP/s
//! against Candle's f32 GEMM rate measured in the same run, for 1 and 2 threads (RAYON_NUM_THREADS).
//!
//! `train`: steps per second and the loader's share of `hush train` in its default configuration (the
//! narrow U-Net from scratch, `demo::train_command`) on a small Cornell box dataset, rendered first when missing.

use std::path::Path;
use std::process::Command;

use crate::baselines;
use crate::bench::{flags, ratio};
use crate::util::{Result, build_hush, ensure_vulkan, load_average, output, project_root, spawn, target_dir};
use crate::util::{read_json, write_json};

pub(crate) fn hush_json(hush: &Path, threads: Option<usize>, args: &[&str]) -> Result<serde_json::Value> {
    let mut cmd = Command::new(hush);
    cmd.arg("bench").args(args);
    if let Some(t) = threads {
        cmd.env("RAYON_NUM_THREADS", t.to_string());
    }
    let text = output(&mut cmd)?;
    serde_json::from_str(&text).map_err(|e| format!("`hush bench {}` printed no JSON: {e}", args.join(" ")))
}

/// The Python helper of the inference rows (the baselines' venv: numpy and pyoidn's bundled OIDN).
/// `inputs DIR W H` writes `color.pfm`, `albedo.pfm` and `normal.pfm` (deterministic noise; the values do
/// not change the cost of dense convolutions); `run CMD...` runs a command once and prints its wall
/// seconds, its peak resident memory (the child's `ru_maxrss`) and its output.
const HELPER: &str = r#"
import json, resource, subprocess, sys, time
import numpy as np
if sys.argv[1] == "inputs":
    out, w, h = sys.argv[2], int(sys.argv[3]), int(sys.argv[4])
    rng = np.random.default_rng(1)
    for name, lo, hi in [("color", 0, 4), ("albedo", 0, 1), ("normal", -1, 1)]:
        a = rng.uniform(lo, hi, (h, w, 3)).astype("<f4")
        with open(f"{out}/{name}.pfm", "wb") as f:
            f.write(b"PF\n%d %d\n-1.0\n" % (w, h))
            f.write(np.ascontiguousarray(a[::-1]).tobytes())
else:
    cmd = sys.argv[2:]
    t = time.perf_counter()
    p = subprocess.run(cmd, capture_output=True, text=True)
    seconds = time.perf_counter() - t
    if p.returncode != 0:
        sys.exit(f"{' '.join(cmd)} failed ({p.returncode}): {p.stderr[-2000:]}")
    peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss * 1024
    print(json.dumps({"seconds": seconds, "peak_rss_bytes": peak, "output": p.stdout + p.stderr}))
"#;

/// OIDN's CPU models and the official weights of each (all with color, albedo and normal). The large
/// model's weights are for clean (prefiltered) features, so OIDN runs it with `--clean_aux`; hush's
/// `Denoiser` runs every TZA file the same way (no prefiltering either way).
const MODELS: [(&str, &str, bool); 3] = [
    ("unet_small", "rt_hdr_alb_nrm_small.tza", false),
    ("unet", "rt_hdr_alb_nrm.tza", false),
    ("unet_large", "rt_hdr_calb_cnrm_large.tza", true),
];

/// Runs the helper (with `LD_LIBRARY_PATH` for OIDN's tools, which its children inherit); its JSON.
pub(crate) fn helper(python: &Path, ld_path: &str, args: &[&str]) -> Result<serde_json::Value> {
    let text = output(Command::new(python).env("LD_LIBRARY_PATH", ld_path).args(["-c", HELPER]).args(args))?;
    if text.trim().is_empty() {
        return Ok(serde_json::Value::Null);
    }
    serde_json::from_str(text.trim()).map_err(|e| format!("the timing helper printed no JSON: {e}"))
}

pub(crate) fn median(xs: &[f64]) -> Option<f64> {
    let mut v: Vec<f64> = xs.iter().copied().filter(|x| x.is_finite()).collect();
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied()
}

/// `oidnDenoise`'s per-execution times (`msec=` after each "Denoising" at `-v 2`), warm-up dropped.
pub(crate) fn oidn_warm_seconds(text: &str) -> Vec<f64> {
    let times: Vec<f64> = text
        .lines()
        .filter_map(|l| l.trim().strip_prefix("msec="))
        .filter_map(|rest| rest.split(',').next()?.parse::<f64>().ok())
        .map(|ms| ms / 1e3)
        .collect();
    times.into_iter().skip(1).collect()
}

/// The inference rows: per model and size, hush's `Denoiser` warm (`hush bench inference --weights`) and
/// OIDN 2.5.1 warm (`oidnDenoise -w` with `-n`: one filter, executed repeatedly), both from the same TZA
/// file on the same PFM inputs with every core; then whole processes at 960² (`hush denoise --model` and
/// `oidnDenoise -w`, PFM in and out, alternating runs).
fn inference(hush: &Path) -> Result<serde_json::Value> {
    let python = baselines::venv_python();
    let oidn = match baselines::oidn_dir() {
        Ok(dir) if python.is_file() => dir,
        Ok(_) | Err(_) => {
            return Ok(serde_json::json!({
                "skipped": format!("OIDN's command-line tools not found (pyoidn in {})", python.display()),
                "install": baselines::SETUP,
            }));
        }
    };
    let oidn_bin = oidn.join("bin/oidnDenoise");
    let ld_path = match std::env::var_os("LD_LIBRARY_PATH") {
        Some(old) => format!("{}:{}", oidn.join("lib").display(), old.to_string_lossy()),
        None => oidn.join("lib").display().to_string(),
    };
    let weights_dir = project_root().join("data/weights/oidn-2.5.1");
    let work = target_dir().join("bench/net-inputs");
    let inputs = |w: usize, h: usize| -> Result<std::path::PathBuf> {
        let dir = work.join(format!("{w}x{h}"));
        if !dir.join("normal.pfm").is_file() {
            std::fs::create_dir_all(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
            helper(&python, &ld_path, &["inputs", &dir.to_string_lossy(), &w.to_string(), &h.to_string()])?;
        }
        Ok(dir)
    };
    let path = |p: std::path::PathBuf| p.to_string_lossy().into_owned();
    let oidn_args = |weights: &str, clean: bool, dir: &Path, out: &str| -> Vec<String> {
        let mut v = vec![path(oidn_bin.clone()), "-w".into(), path(weights_dir.join(weights))];
        for (flag, name) in [("--hdr", "color"), ("--alb", "albedo"), ("--nrm", "normal")] {
            v.push(flag.into());
            v.push(path(dir.join(format!("{name}.pfm"))));
        }
        if clean {
            v.push("--clean_aux".into());
        }
        v.extend(["-o".into(), out.into()]);
        v
    };
    let run = |cmd: &[String]| -> Result<serde_json::Value> {
        let args: Vec<&str> = std::iter::once("run").chain(cmd.iter().map(String::as_str)).collect();
        helper(&python, &ld_path, &args)
    };
    let mut warm = Vec::new();
    for (w, h, runs) in [(512usize, 512usize, 5usize), (1920, 1080, 5)] {
        let dir = inputs(w, h)?;
        for (kind, weights, clean) in MODELS {
            let hush_row = hush_json(
                hush,
                None,
                &[
                    "inference",
                    "--weights",
                    &path(weights_dir.join(weights)),
                    "--size",
                    &w.to_string(),
                    "--height",
                    &h.to_string(),
                    "--runs",
                    &runs.to_string(),
                ],
            )?;
            let mut cmd = oidn_args(weights, clean, &dir, &path(dir.join("oidn-out.pfm")));
            cmd.extend(["-n".into(), (runs + 1).to_string(), "-v".into(), "2".into()]);
            let oidn_row = run(&cmd)?;
            let oidn_times = oidn_warm_seconds(oidn_row["output"].as_str().unwrap_or_default());
            let oidn_seconds = median(&oidn_times);
            let hush_seconds = hush_row["seconds"].as_f64();
            warm.push(serde_json::json!({
                "model": kind, "weights": weights, "width": w, "height": h,
                "setting": format!("{w}x{h}, color + albedo + normal from {weights}, warm: median of {runs} \
                                    executions after one warm-up, every core{}",
                                   if clean { "; OIDN with --clean_aux (the weights' features)" } else { "" }),
                "hush_seconds": hush_seconds, "hush_runs_seconds": hush_row["runs_seconds"],
                "hush_peak_rss_bytes": hush_row["peak_rss_bytes"],
                "hush_direct_convolutions": hush_row["direct_convolutions"],
                "oidn_seconds": oidn_seconds, "oidn_runs_seconds": oidn_times,
                "oidn_peak_rss_bytes": oidn_row["peak_rss_bytes"],
                "hush_over_oidn_seconds": ratio(&serde_json::json!(hush_seconds), &serde_json::json!(oidn_seconds)),
                "hush_over_oidn_peak_rss":
                    ratio(&hush_row["peak_rss_bytes"], &oidn_row["peak_rss_bytes"]),
            }));
        }
    }
    // Whole processes, 960², unet: alternating single runs so that drift in the machine's speed hits both.
    let (w, h) = (960usize, 960usize);
    let dir = inputs(w, h)?;
    let weights = "rt_hdr_alb_nrm.tza";
    let hush_cmd: Vec<String> = vec![
        path(hush.to_path_buf()),
        "denoise".into(),
        "--model".into(),
        path(weights_dir.join(weights)),
        "--color".into(),
        path(dir.join("color.pfm")),
        "--albedo".into(),
        path(dir.join("albedo.pfm")),
        "--normal".into(),
        path(dir.join("normal.pfm")),
        "--out".into(),
        path(dir.join("hush-out.pfm")),
    ];
    let oidn_cmd = oidn_args(weights, false, &dir, &path(dir.join("oidn-out.pfm")));
    let (mut hush_s, mut oidn_s, mut hush_rss, mut oidn_rss) = (Vec::new(), Vec::new(), 0f64, 0f64);
    for _ in 0..5 {
        let a = run(&hush_cmd)?;
        let b = run(&oidn_cmd)?;
        hush_s.extend(a["seconds"].as_f64());
        oidn_s.extend(b["seconds"].as_f64());
        hush_rss = hush_rss.max(a["peak_rss_bytes"].as_f64().unwrap_or(0.0));
        oidn_rss = oidn_rss.max(b["peak_rss_bytes"].as_f64().unwrap_or(0.0));
    }
    let whole = serde_json::json!({
        "model": "unet", "weights": weights, "width": w, "height": h,
        "setting": "whole processes, 960x960 PFM color + albedo + normal in, PFM out: `hush denoise --model` \
                    against `oidnDenoise -w`, 5 alternating runs each, median wall seconds, largest peak RSS",
        "hush_seconds": median(&hush_s), "hush_runs_seconds": hush_s, "hush_peak_rss_bytes": hush_rss,
        "oidn_seconds": median(&oidn_s), "oidn_runs_seconds": oidn_s, "oidn_peak_rss_bytes": oidn_rss,
        "hush_over_oidn_seconds": ratio(&serde_json::json!(median(&hush_s)), &serde_json::json!(median(&oidn_s))),
        "hush_over_oidn_peak_rss": ratio(&serde_json::json!(hush_rss), &serde_json::json!(oidn_rss)),
    });
    Ok(serde_json::json!({
        "implementation": "OIDN 2.5.1 (pyoidn's bundled oidnDenoise) against hush, the same TZA weights",
        "warm": warm,
        "whole_process": whole,
        "goal": "hush_over_oidn_seconds <= 1.0 for unet warm at 512x512 and 1920x1080 and for the whole \
                 process at 960x960; hush_over_oidn_peak_rss <= 1.0",
    }))
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
    let inference = inference(&hush)?;
    let thread_counts = [1usize, 2];
    let mut train = Vec::new();
    let mut gemm = Vec::new();
    for &t in &thread_counts {
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
    let (train_threads, best_train) = fastest(&train);
    let gemm_at = |t: usize| gemm.iter().find(|g| g.0 == t).map(|g| g.1.clone()).unwrap_or_default();
    let per_threads = |v: &[(usize, serde_json::Value)]| {
        serde_json::Value::Object(v.iter().map(|(t, j)| (t.to_string(), j.clone())).collect())
    };
    let result = serde_json::json!({
        "benchmark": "net",
        "inference": inference,
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
