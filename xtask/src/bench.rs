//! `cargo xtask bench render`: hush against Mitsuba 3, and hush's specialized kernel against its
//! generic one, on the Cornell box, veach-mis and living-room, in one run.
//!
//! Each scene is rendered from its own file by both renderers at the same size, max_depth 8 and
//! spp, chosen per scene (`SCENES`; `--spp N` sets every scene's) so the default run takes
//! minutes: hush's kernel specialized to the scene and Mitsuba 3 (`llvm_ad_rgb`, 2 threads), alternately
//! `--repeats` times (3), then hush's `--generic` kernel once. A timed render lasts a few seconds, and
//! on a shared machine one measurement moves by up to 20 %: each scene's hush/Mitsuba ratio is the
//! median of its back-to-back pairs' ratios, each renderer's figures those of its median run, and
//! every run is recorded (`runs`, `mpaths_per_cpu_second_pairs`).
//! Mitsuba gets the size and depth the way hush's flags set them, the `path` integrator, and a box
//! in place of a pixel filter hush lacks (box, tent and gaussian are kept): `load_scene` in
//! `xtask/mitsuba_tool.py`, which lists its edits in the JSON.
//! Reported per renderer: M paths (= samples) per CPU-second and, where an independent reference
//! exists (the box: Mitsuba's 1792-spp render in `../shared/reference/mitsuba-cbox`),
//! relMSE × CPU-seconds. CPU-seconds count every thread of the process: hush's from its own stats
//! (after the scene load and the GPU set-up, with the upload and BVH build, of a render whose
//! kernel an untimed 1-spp render in the same process compiled first: `hush render --warm-up`,
//! whose CPU-seconds are recorded beside as `warm_up_cpu_seconds`), Mitsuba's from getrusage around
//! a second render whose kernels come from Dr.Jit's cache (see `xtask/mitsuba_tool.py`; its scene
//! load, BVH build and first render, `cold_render_cpu_seconds`, are not counted). relMSE is computed by
//! Python in Mitsuba's venv (xtask reads no EXR). Without Mitsuba the hush half still runs and
//! Mitsuba is reported as skipped with the command that installs it; without `../shared`, only
//! the box runs.

use std::process::Command;

use crate::args::{Flags, Takes};
use crate::mitsuba;
use crate::util::{
    Result, build_hush, ensure_vulkan, load_average, output, project_root, read_json, spawn, target_dir, write_json,
};

/// The usage of each benchmark.
const USAGE: [&str; 5] = [
    "bench render [--release] [--spp N (every scene)] [--repeats N] [--only NAME] [--no-mitsuba] [--no-build]",
    "bench dataset [--release] [--size N] [--views N] [--procedural N] [--hush PATH]",
    "bench net [--release]",
    "bench train [--release] [--steps N]",
    "bench finetune [--release] [--steps N]",
];

/// The flags of benchmark `which` (an index into [`USAGE`]) parsed from `args`.
pub fn flags(args: &[String], which: usize) -> Result<Flags> {
    use Takes::{Nothing, Number, Value};
    let known: &[(&str, Takes)] = match which {
        0 => &[
            ("--release", Nothing),
            ("--spp", Number),
            ("--repeats", Number),
            ("--only", Value),
            ("--no-mitsuba", Nothing),
            ("--no-build", Nothing),
        ],
        1 => &[
            ("--release", Nothing),
            ("--size", Number),
            ("--views", Number),
            ("--procedural", Number),
            ("--hush", Value),
        ],
        2 => &[("--release", Nothing)],
        _ => &[("--release", Nothing), ("--steps", Number)],
    };
    Flags::parse(args, known, 0, &format!("cargo xtask {}", USAGE[which]))
}

pub fn run(args: &[String]) -> Result<()> {
    match args.first().map(String::as_str) {
        Some("render") => render(&args[1..]),
        Some("dataset") => dataset(&args[1..]),
        Some("net") => crate::bench_net::net(&args[1..]),
        Some("train") => crate::bench_net::train(&args[1..]),
        Some("finetune") => crate::bench_finetune::run(&args[1..]),
        _ => Err(format!("usage: cargo xtask {}", USAGE.join("\n       cargo xtask "))),
    }
}

/// `a / b` as JSON, or null where either is missing or `b` is not positive.
pub(crate) fn ratio(a: &serde_json::Value, b: &serde_json::Value) -> serde_json::Value {
    match (a.as_f64(), b.as_f64()) {
        (Some(a), Some(b)) if b > 0.0 => serde_json::json!(a / b),
        _ => serde_json::Value::Null,
    }
}

/// A scene of `bench render`: where it is, and the settings both renderers use.
struct BenchScene {
    name: &'static str,
    /// Relative to the repository root, or to `../shared` with `shared`; empty for a procedural scene.
    path: &'static str,
    shared: bool,
    /// The seed of `hush scene generate --seed N` (default generator options), written under
    /// `target/bench/scenes/` first, in place of `path`.
    procedural: Option<u64>,
    width: u32,
    height: u32,
    spp: u32,
    /// Why this scene and these settings.
    note: &'static str,
}

/// The scenes, sized so that hush takes about a minute or less on each under light load on 2 cores.
const SCENES: [BenchScene; 7] = [
    BenchScene {
        name: "cbox",
        path: "data/scenes/cbox/scene.xml",
        shared: false,
        procedural: None,
        width: 512,
        height: 512,
        spp: 64,
        note: "Mitsuba 3's Cornell box, 36 triangles: the issue's reference setting",
    },
    BenchScene {
        name: "veach-mis",
        path: "scenes/veach-mis/scene.xml",
        shared: true,
        procedural: None,
        width: 384,
        height: 216,
        spp: 32,
        note: "cubes and rectangles (120 triangles), rough conductors, four analytic sphere lights from 7.6 to \
               3040 W/sr/m²",
    },
    BenchScene {
        name: "living-room",
        path: "scenes/living-room/scene.xml",
        shared: true,
        procedural: None,
        width: 384,
        height: 216,
        spp: 8,
        note: "143k triangles (BVH-bound), lit only by an environment map",
    },
    BenchScene {
        name: "spheres-sky",
        path: "data/tests/mitsuba/spheres-sky/scene.xml",
        shared: false,
        procedural: None,
        width: 256,
        height: 192,
        spp: 256,
        note: "four analytic spheres (diffuse, plastic, rough gold, glass) on a rectangle under a constant sky",
    },
    BenchScene {
        name: "procedural-1",
        path: "",
        shared: false,
        procedural: Some(1),
        width: 256,
        height: 256,
        spp: 32,
        note: "`hush scene generate --seed 1`: a room of boxes, tables, shelves, spheres and cylinders",
    },
    BenchScene {
        name: "procedural-2",
        path: "",
        shared: false,
        procedural: Some(2),
        width: 256,
        height: 256,
        spp: 32,
        note: "`hush scene generate --seed 2`",
    },
    BenchScene {
        name: "procedural-3",
        path: "",
        shared: false,
        procedural: Some(3),
        width: 256,
        height: 256,
        spp: 32,
        note: "`hush scene generate --seed 3`",
    },
];

/// How many times `bench render` alternates hush's specialized kernel with Mitsuba on each scene by default.
const REPEATS: u32 = 3;

/// The run of `runs` whose `key` is the median (the upper one of an even count); a run without it (a
/// skipped peer) is returned as it is.
fn median_run(runs: &[serde_json::Value], key: &str) -> serde_json::Value {
    let mut rated: Vec<&serde_json::Value> =
        runs.iter().filter(|r| r[key].as_f64().is_some_and(f64::is_finite)).collect();
    if rated.is_empty() {
        return runs.first().cloned().unwrap_or(serde_json::Value::Null);
    }
    rated.sort_by(|a, b| a[key].as_f64().unwrap_or(0.0).total_cmp(&b[key].as_f64().unwrap_or(0.0)));
    rated[rated.len() / 2].clone()
}

/// Every scene at its settings, max_depth 8; `render.json` holds one entry per scene.
fn render(args: &[String]) -> Result<()> {
    const MAX_DEPTH: u32 = 8;
    let flags = flags(args, 0)?;
    ensure_vulkan()?;
    let release = flags.has("--release");
    let hush = if flags.has("--no-build") {
        // The binary as last built (e.g. while the workspace is mid-edit).
        target_dir().join(if release { "release" } else { "debug" }).join("hush")
    } else {
        build_hush(release)?
    };
    let spp_override = if flags.has("--spp") { Some(flags.number("--spp", 0)?) } else { None };
    let skip_mitsuba = flags.has("--no-mitsuba");
    let repeats: u32 = flags.number("--repeats", REPEATS)?;
    if repeats == 0 {
        return Err("--repeats must be at least 1".into());
    }
    let dir = target_dir().join("bench");
    std::fs::create_dir_all(&dir).map_err(|e| e.to_string())?;
    let load_before = load_average();
    let mut results = Vec::new();
    let only = flags.value("--only").map(str::to_string);
    for sc in SCENES.iter().filter(|sc| only.as_deref().is_none_or(|o| o == sc.name)) {
        let scene = match (sc.shared, mitsuba::shared_dir()) {
            _ if let Some(seed) = sc.procedural => {
                let file = dir.join("scenes").join(sc.name).join("scene.xml");
                spawn(
                    Command::new(&hush).args(["scene", "generate", "--seed", &seed.to_string(), "--out"]).arg(&file),
                )?;
                file
            }
            (false, _) => project_root().join(sc.path),
            (true, Some(shared)) => shared.join(sc.path),
            (true, None) => {
                eprintln!("xtask: {} skipped: ../shared (beside the repository) is missing", sc.name);
                results.push(serde_json::json!({ "scene": sc.name, "skipped": "../shared is missing" }));
                continue;
            }
        };
        let spp = spp_override.unwrap_or(sc.spp);
        let reference = if sc.name == "cbox" { mitsuba::cbox_reference() } else { None };
        let size = [sc.width.to_string(), sc.height.to_string(), MAX_DEPTH.to_string(), spp.to_string()];
        let load_start = load_average();

        // hush's specialized kernel and Mitsuba, alternately, then hush's generic kernel once.
        let hush_render = |generic: bool, run: u32| -> Result<(std::path::PathBuf, serde_json::Value)> {
            let kind = if generic { "generic" } else { "specialized" };
            let stats = dir.join(format!("render-hush-{}-{kind}.json", sc.name));
            let exr = dir.join(format!("render-hush-{}-{kind}.exr", sc.name));
            let mut cmd = Command::new(&hush);
            cmd.arg("render").arg(&scene).args(["--spp", &size[3], "--width", &size[0], "--height", &size[1]]);
            cmd.args(["--max-depth", &size[2], "--out"]).arg(&exr).arg("--stats").arg(&stats);
            if generic {
                cmd.arg("--generic");
            }
            // The kernel is compiled by an untimed 1-spp render in the same process first, as Mitsuba's
            // timed render is its second in one process and reuses its JIT's kernels.
            cmd.arg("--warm-up");
            spawn(&mut cmd)?;
            let s = read_json(&stats)?;
            Ok((
                exr,
                serde_json::json!({
                    "run": run,
                    "mpaths_per_cpu_second": s["mpaths_per_cpu_second"],
                    "mpaths_per_second": s["mpaths_per_second"],
                    "cpu_seconds": s["cpu_seconds"],
                    "warm_up_cpu_seconds": s["warm_up_cpu_seconds"],
                    "wall_seconds": s["wall_seconds"],
                    "non_finite_values": s["non_finite_values"],
                    "adapter": s["adapter"],
                }),
            ))
        };
        let mitsuba_render = |run: u32| -> Result<serde_json::Value> {
            let mut py = match mitsuba::python() {
                _ if skip_mitsuba => return Ok(serde_json::json!({ "skipped": "--no-mitsuba" })),
                Err(e) => {
                    eprintln!("xtask: Mitsuba skipped: {e}");
                    return Ok(serde_json::json!({ "skipped": e, "install": mitsuba::SETUP }));
                }
                Ok(py) => py,
            };
            let mstats = dir.join(format!("render-mitsuba-{}.json", sc.name));
            py.arg(mitsuba::helper()).arg("bench").arg("--scene").arg(&scene);
            py.args(["--spp", &size[3], "--width", &size[0], "--height", &size[1], "--max-depth", &size[2]]);
            py.args(["--threads", "2", "--out"]).arg(dir.join(format!("render-mitsuba-{}.exr", sc.name)));
            py.arg("--stats").arg(&mstats);
            if let Some(reference) = &reference {
                py.arg("--ref").arg(reference);
            }
            py.stdout(std::process::Stdio::null());
            spawn(&mut py)?;
            let mut m = read_json(&mstats)?;
            m["run"] = run.into();
            Ok(m)
        };
        let mut hush_runs = Vec::new();
        let mut mitsuba_runs = Vec::new();
        let mut hush_exr = None;
        for run in 0..repeats {
            // Every run renders the same image (same seed and settings).
            let (exr, h) = hush_render(false, run)?;
            hush_exr = Some(exr);
            hush_runs.push(h);
            mitsuba_runs.push(mitsuba_render(run)?);
        }
        let hush_exr = hush_exr.expect("repeats ≥ 1");
        let pair_ratios: Vec<serde_json::Value> = hush_runs
            .iter()
            .zip(&mitsuba_runs)
            .map(|(h, m)| ratio(&h["mpaths_per_cpu_second"], &m["msamples_per_cpu_second"]))
            .collect();
        let mut hush_result = median_run(&hush_runs, "mpaths_per_cpu_second");
        hush_result["runs"] = hush_runs.clone().into();
        let mut mitsuba_result = median_run(&mitsuba_runs, "msamples_per_cpu_second");
        if mitsuba_result.get("skipped").is_none() {
            mitsuba_result["runs"] = mitsuba_runs.clone().into();
        }
        let load_between = load_average();
        let generic_result = hush_render(true, 0)?.1;

        // relMSE for hush's image (needs Mitsuba's venv).
        if let (Some(reference), Ok(mut py), false) = (&reference, mitsuba::python(), skip_mitsuba) {
            let text = output(
                py.arg(mitsuba::helper()).args(["relmse", "--image"]).arg(&hush_exr).arg("--ref").arg(reference),
            )?;
            let r: serde_json::Value = serde_json::from_str(text.trim().lines().last().unwrap_or_default())
                .map_err(|e| format!("relmse printed no JSON: {e}"))?;
            hush_result["relmse"] = r["relmse"].clone();
            hush_result["relmse_x_cpu_seconds"] = match (r["relmse"].as_f64(), hush_result["cpu_seconds"].as_f64()) {
                (Some(r), Some(c)) => serde_json::json!(r * c),
                _ => serde_json::Value::Null,
            };
        }
        if hush_result.get("relmse").is_none() {
            hush_result["relmse"] = match &reference {
                None => "no independent reference for this scene".into(),
                Some(_) => format!("skipped: computed in Mitsuba's venv ({})", mitsuba::SETUP).into(),
            };
        }
        results.push(serde_json::json!({
            "scene": sc.name,
            "file": scene.display().to_string(),
            "note": sc.note,
            "width": sc.width, "height": sc.height, "max_depth": MAX_DEPTH, "spp": spp,
            "reference": reference.as_ref().map(|p| p.display().to_string()),
            "load_average": { "before": load_start, "between": load_between, "after": load_average() },
            "hush": hush_result,
            "hush_generic": generic_result,
            "mitsuba": mitsuba_result,
            "hush_over_mitsuba": {
                "mpaths_per_cpu_second": crate::bench_net::median(
                    &pair_ratios.iter().filter_map(serde_json::Value::as_f64).collect::<Vec<_>>()),
                "mpaths_per_cpu_second_pairs": pair_ratios,
                "relmse_x_cpu_seconds":
                    ratio(&hush_result["relmse_x_cpu_seconds"], &mitsuba_result["relmse_x_cpu_seconds"]),
            },
            "specialized_over_generic": {
                "mpaths_per_cpu_second":
                    ratio(&hush_result["mpaths_per_cpu_second"], &generic_result["mpaths_per_cpu_second"]),
                "mpaths_per_second": ratio(&hush_result["mpaths_per_second"], &generic_result["mpaths_per_second"]),
            },
        }));
    }

    let result = serde_json::json!({
        "benchmark": "render",
        "relmse": "mean over pixels and R, G, B of (x − ref)² / (ref² + 1e-2)",
        "note": "hush_over_mitsuba: paths per CPU-second, higher is better for hush (goal ≥ 1), the median of the \
                 ratios of `repeats` back-to-back pairs (each in mpaths_per_cpu_second_pairs); relMSE × CPU-seconds, \
                 lower is better (goal ≤ 1), of the median runs. hush and mitsuba: the run with the median rate, all \
                 runs in `runs`. specialized_over_generic: > 1 means the kernel specialized to the scene is faster \
                 (median run against the one generic run). Compare ratios measured minutes apart with the load \
                 averages.",
        "repeats": repeats,
        "load_average": { "before": load_before, "after": load_average() },
        "scenes": results,
    });
    let out = dir.join("render.json");
    write_json(&out, &result)?;
    println!("{}", serde_json::to_string_pretty(&result).expect("serializes"));
    println!("written to {}", out.display());
    Ok(())
}

/// `cargo xtask bench dataset`: perspectives per hour of `hush dataset` in its default configuration (spp
/// ladder 1..256, features at 64 spp, references at 1024 spp with 2×2 supersampling) on the Cornell box,
/// or with `--procedural N` on N generated scenes (`hush dataset --procedural N`, seed 0),
/// `--views` perspectives per scene (default 2: the scene camera and one generated view) at `--size`² (default 128;
/// the cost per perspective grows with the pixel count, so the figure at 512² is reported as an
/// extrapolation). Wall seconds include scene loading and GPU set-up; the render seconds come from the
/// manifest. `--hush PATH` runs another build (an earlier commit's) with the same settings. Written to
/// `target/bench/dataset-cbox.json` or `dataset-procedural.json`.
fn dataset(args: &[String]) -> Result<()> {
    let flags = flags(args, 1)?;
    ensure_vulkan()?;
    // Another build of hush (an earlier commit's, to compare with) runs with the same settings.
    let hush = match flags.value("--hush") {
        Some(path) => std::path::PathBuf::from(path),
        None => build_hush(flags.has("--release"))?,
    };
    let (size, views): (u32, u32) = (flags.number("--size", 128)?, flags.number("--views", 2)?);
    let procedural: u32 = flags.number("--procedural", 0)?;
    let dir = target_dir().join("bench");
    let name = if procedural > 0 { "procedural" } else { "cbox" };
    let out = dir.join(format!("dataset-{name}"));
    let _ = std::fs::remove_dir_all(&out);
    std::fs::create_dir_all(&dir).map_err(|e| e.to_string())?;
    let load_before = load_average();
    let start = std::time::Instant::now();
    let mut cmd = Command::new(&hush);
    cmd.arg("dataset");
    if procedural > 0 {
        // Seeded scenes (seed 0), generated by the same build that renders them.
        cmd.args(["--procedural", &procedural.to_string()]);
    } else {
        cmd.arg(project_root().join("data/scenes/cbox/scene.xml"));
    }
    spawn(cmd.arg("--out").arg(&out).args(["--views", &views.to_string(), "--size", &size.to_string()]))?;
    let wall = start.elapsed().as_secs_f64();
    let manifest = read_json(&out.join("manifest.json"))?;
    let recorded = manifest["views"].as_array().map_or(0, Vec::len);
    let perspectives = views as usize * if procedural > 0 { procedural as usize } else { 1 };
    if recorded != perspectives {
        return Err(format!("{}: {recorded} views recorded, {perspectives} expected", out.display()));
    }
    let mut render_seconds = 0.0;
    for v in manifest["views"].as_array().into_iter().flatten() {
        let noisy: f64 = v["noisy"].as_array().into_iter().flatten().filter_map(|r| r["render_seconds"].as_f64()).sum();
        render_seconds += noisy
            + v["aux"]["render_seconds"].as_f64().unwrap_or(0.0)
            + v["reference"]["render_seconds"].as_f64().unwrap_or(0.0);
    }
    let per_hour = 3600.0 * perspectives as f64 / wall;
    let scale = (size as f64 * size as f64) / (512.0 * 512.0);
    let result = serde_json::json!({
        "benchmark": "dataset",
        "scene": if procedural > 0 {
            format!("{procedural} procedural scenes (hush dataset --procedural {procedural}, seed 0)")
        } else {
            "cbox (Mitsuba 3 Cornell box)".to_string()
        },
        "hush": hush.display().to_string(),
        "configuration": manifest["config"],
        "size": size,
        "views": views,
        "perspectives": perspectives,
        "wall_seconds": wall,
        "render_seconds": render_seconds,
        "perspectives_per_hour": per_hour,
        "perspectives_per_hour_at_512_extrapolated": per_hour * scale,
        "load_average_before": load_before,
        "load_average_after": load_average(),
    });
    let path = dir.join(format!("dataset-{name}.json"));
    write_json(&path, &result)?;
    println!("{}", serde_json::to_string_pretty(&result).expect("serializes"));
    println!("written to {}", path.display());
    Ok(())
}
