//! `cargo xtask bench render`: hush against Mitsuba 3 on the Cornell box, in one run.
//!
//! Both render `data/scenes/cbox/scene.xml` at 512², max_depth 8, the same spp (64 unless
//! `--spp`). Reported per renderer: M paths (= samples) per CPU-second, and relMSE × CPU-seconds
//! against Mitsuba's independent 1792-spp render (`../shared/reference/mitsuba-cbox`). CPU-seconds
//! count every thread of the process: hush's from its own stats (after the scene load and the GPU
//! set-up), Mitsuba's (`llvm_ad_rgb`, 2 threads) from getrusage around a second render whose
//! kernels come from Dr.Jit's cache (see `xtask/mitsuba_tool.py`). relMSE is computed by Python in
//! Mitsuba's venv (xtask reads no EXR). Without Mitsuba the hush half still runs and Mitsuba is
//! reported as skipped with the command that installs it.

use std::process::Command;

use crate::mitsuba;
use crate::util::{
    Result, build_hush, ensure_vulkan, load_average, output, project_root, read_json, release, spawn, target_dir,
    write_json,
};

pub fn run(args: &[String]) -> Result<()> {
    match args.first().map(String::as_str) {
        Some("render") => render(&args[1..]),
        Some("dataset") => dataset(&args[1..]),
        Some("net") => crate::bench_net::net(&args[1..]),
        Some("train") => crate::bench_net::train(&args[1..]),
        _ => Err("usage: cargo xtask bench render [--release] [--spp N] [--no-mitsuba] [--no-build]\n       \
                  cargo xtask bench dataset [--release] [--size N] [--views N]\n       \
                  cargo xtask bench net [--release]\n       \
                  cargo xtask bench train [--release] [--steps N]"
            .into()),
    }
}

fn spp_arg(args: &[String], default: u32) -> Result<u32> {
    match args.iter().position(|a| a == "--spp") {
        Some(i) => args.get(i + 1).and_then(|s| s.parse().ok()).ok_or_else(|| "--spp needs a number".to_string()),
        None => Ok(default),
    }
}

fn ratio(a: &serde_json::Value, b: &serde_json::Value) -> serde_json::Value {
    match (a.as_f64(), b.as_f64()) {
        (Some(a), Some(b)) if b > 0.0 => serde_json::json!(a / b),
        _ => serde_json::Value::Null,
    }
}

/// The box at 512², max_depth 8.
fn render(args: &[String]) -> Result<()> {
    ensure_vulkan()?;
    let hush = if args.iter().any(|a| a == "--no-build") {
        // The binary as last built (e.g. while the workspace is mid-edit).
        target_dir().join(if release(args) { "release" } else { "debug" }).join("hush")
    } else {
        build_hush(release(args))?
    };
    let spp = spp_arg(args, 64)?;
    let dir = target_dir().join("bench");
    let scene = project_root().join("data/scenes/cbox/scene.xml");
    let reference = mitsuba::cbox_reference();
    std::fs::create_dir_all(&dir).map_err(|e| e.to_string())?;
    let load_before = load_average();

    // hush.
    let stats = dir.join("render-hush-cbox.json");
    let hush_exr = dir.join("render-cbox.exr");
    spawn(
        Command::new(&hush)
            .args(["render"])
            .arg(&scene)
            .args(["--spp", &spp.to_string(), "--width", "512", "--height", "512", "--max-depth", "8", "--out"])
            .arg(&hush_exr)
            .arg("--stats")
            .arg(&stats),
    )?;
    let s = read_json(&stats)?;
    let mut hush_result = serde_json::json!({
        "mpaths_per_cpu_second": s["mpaths_per_cpu_second"],
        "mpaths_per_second": s["mpaths_per_second"],
        "cpu_seconds": s["cpu_seconds"],
        "wall_seconds": s["wall_seconds"],
        "adapter": s["adapter"],
    });
    let load_between = load_average();

    // Mitsuba, and relMSE for both (both need Mitsuba's venv).
    let skip = args.iter().any(|a| a == "--no-mitsuba");
    let mitsuba_result = match mitsuba::python() {
        _ if skip => serde_json::json!({ "skipped": "--no-mitsuba" }),
        Err(e) => {
            eprintln!("xtask: Mitsuba skipped: {e}");
            hush_result["relmse"] = format!("skipped: computed in Mitsuba's venv ({})", mitsuba::SETUP).into();
            serde_json::json!({ "skipped": e, "install": mitsuba::SETUP })
        }
        Ok(mut py) => {
            if let Some(reference) = &reference {
                let text = output(
                    mitsuba::python()?
                        .arg(mitsuba::helper())
                        .args(["relmse", "--image"])
                        .arg(&hush_exr)
                        .arg("--ref")
                        .arg(reference),
                )?;
                let r: serde_json::Value = serde_json::from_str(text.trim().lines().last().unwrap_or_default())
                    .map_err(|e| format!("relmse printed no JSON: {e}"))?;
                let relmse = r["relmse"].as_f64();
                let cpu = s["cpu_seconds"].as_f64();
                hush_result["relmse"] = r["relmse"].clone();
                hush_result["nonfinite_values"] = r["nonfinite_values"].clone();
                hush_result["relmse_x_cpu_seconds"] = match (relmse, cpu) {
                    (Some(r), Some(c)) => serde_json::json!(r * c),
                    _ => serde_json::Value::Null,
                };
            }
            let mstats = dir.join("render-mitsuba-cbox.json");
            py.arg(mitsuba::helper())
                .arg("bench")
                .arg("--scene")
                .arg(&scene)
                .args(["--spp", &spp.to_string(), "--threads", "2", "--out"])
                .arg(dir.join("render-mitsuba-cbox.exr"))
                .arg("--stats")
                .arg(&mstats);
            if let Some(reference) = &reference {
                py.arg("--ref").arg(reference);
            }
            py.stdout(std::process::Stdio::null());
            spawn(&mut py)?;
            read_json(&mstats)?
        }
    };
    if reference.is_none() {
        hush_result["relmse"] = "skipped: ../shared/reference/mitsuba-cbox/mitsuba_1792spp.exr not found".into();
    }

    let hush_over_mitsuba = serde_json::json!({
        "mpaths_per_cpu_second": ratio(&hush_result["mpaths_per_cpu_second"], &mitsuba_result["msamples_per_cpu_second"]),
        "relmse_x_cpu_seconds": ratio(&hush_result["relmse_x_cpu_seconds"], &mitsuba_result["relmse_x_cpu_seconds"]),
        "note": "paths per CPU-second: higher is better for hush (goal ≥ 1); relMSE × CPU-seconds: lower is better (goal ≤ 1)",
    });
    let result = serde_json::json!({
        "benchmark": "render",
        "scene": "cbox (Mitsuba 3 Cornell box)",
        "width": 512, "height": 512, "max_depth": 8, "spp": spp,
        "reference": reference.as_ref().map(|p| p.display().to_string()),
        "relmse": "mean over pixels and R, G, B of (x − ref)² / (ref² + 1e-2)",
        "load_average": { "before": load_before, "between": load_between, "after": load_average() },
        "hush": hush_result,
        "mitsuba": mitsuba_result,
        "hush_over_mitsuba": hush_over_mitsuba,
    });
    let out = dir.join("render.json");
    write_json(&out, &result)?;
    println!("{}", serde_json::to_string_pretty(&result).expect("serializes"));
    println!("written to {}", out.display());
    Ok(())
}

/// `cargo xtask bench dataset`: perspectives per hour of `hush dataset` in its default configuration (spp
/// ladder 1..256, features at 64 spp, references at 1024 spp with 2×2 supersampling) on the Cornell box,
/// `--views` perspectives (default 2: the scene camera and one generated view) at `--size`² (default 128;
/// the cost per perspective grows with the pixel count, so the figure at 512² is reported as an
/// extrapolation). Wall seconds include scene loading and GPU set-up; the render seconds come from the
/// manifest.
fn dataset(args: &[String]) -> Result<()> {
    ensure_vulkan()?;
    let hush = build_hush(release(args))?;
    let num = |flag: &str, default: u32| -> Result<u32> {
        match args.iter().position(|a| a == flag) {
            Some(i) => args.get(i + 1).and_then(|s| s.parse().ok()).ok_or_else(|| format!("{flag} needs a number")),
            None => Ok(default),
        }
    };
    let (size, views) = (num("--size", 128)?, num("--views", 2)?);
    let dir = target_dir().join("bench");
    let out = dir.join("dataset-cbox");
    let _ = std::fs::remove_dir_all(&out);
    std::fs::create_dir_all(&dir).map_err(|e| e.to_string())?;
    let scene = project_root().join("data/scenes/cbox/scene.xml");
    let load_before = load_average();
    let start = std::time::Instant::now();
    spawn(Command::new(&hush).arg("dataset").arg(&scene).arg("--out").arg(&out).args([
        "--views",
        &views.to_string(),
        "--size",
        &size.to_string(),
    ]))?;
    let wall = start.elapsed().as_secs_f64();
    let manifest = read_json(&out.join("manifest.json"))?;
    let recorded = manifest["views"].as_array().map_or(0, Vec::len);
    if recorded != views as usize {
        return Err(format!("{}: {recorded} views recorded, {views} expected", out.display()));
    }
    let mut render_seconds = 0.0;
    for v in manifest["views"].as_array().into_iter().flatten() {
        let noisy: f64 = v["noisy"].as_array().into_iter().flatten().filter_map(|r| r["render_seconds"].as_f64()).sum();
        render_seconds += noisy
            + v["aux"]["render_seconds"].as_f64().unwrap_or(0.0)
            + v["reference"]["render_seconds"].as_f64().unwrap_or(0.0);
    }
    let per_hour = 3600.0 * views as f64 / wall;
    let scale = (size as f64 * size as f64) / (512.0 * 512.0);
    let result = serde_json::json!({
        "benchmark": "dataset",
        "scene": "cbox (Mitsuba 3 Cornell box)",
        "configuration": manifest["config"],
        "size": size,
        "views": views,
        "wall_seconds": wall,
        "render_seconds": render_seconds,
        "perspectives_per_hour": per_hour,
        "perspectives_per_hour_at_512_extrapolated": per_hour * scale,
        "load_average_before": load_before,
        "load_average_after": load_average(),
    });
    let path = dir.join("dataset.json");
    write_json(&path, &result)?;
    println!("{}", serde_json::to_string_pretty(&result).expect("serializes"));
    println!("written to {}", path.display());
    Ok(())
}
