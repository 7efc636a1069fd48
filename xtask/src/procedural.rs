//! `cargo xtask procedural check`: procedural scenes load and render without NaN or Inf, and differ.
//!
//! For seeds S, S+1, …, S+count−1 it spawns `hush scene generate` (which probes each scene on the GPU) and
//! `hush render --stats` at a tiny size and low spp, then reports in `target/procedural/summary.json` the
//! spread of the scenes' mean luminance (min, 10th percentile, median, 90th percentile, max), the share of
//! each material class among all surfaces and the share of scenes that contain it, the light kinds and the
//! styles. It fails when a scene does not generate or render, when an image has a NaN or Inf, or when two
//! scenes are identical.

use std::collections::{BTreeMap, BTreeSet};
use std::path::PathBuf;
use std::process::Command;
use std::time::Instant;

use crate::args::{Flags, Takes};
use crate::util::{Result, build_hush, ensure_vulkan, read_json, target_dir, write_json};

const USAGE: &str = "usage: cargo xtask procedural check [--count N] [--seed S] [--size PX] [--spp N] \
                     [--ingredients default|basic|...] [--release] [--hush PATH]";

pub fn run(args: &[String]) -> Result<()> {
    match args.first().map(String::as_str) {
        Some("check") => check(&args[1..]),
        _ => Err(USAGE.into()),
    }
}

/// The `q`-quantile (0..=1) of sorted values, by the nearest rank.
fn quantile(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    sorted[((sorted.len() - 1) as f64 * q).round() as usize]
}

/// Runs a command quietly; on failure returns its standard error.
fn quiet(cmd: &mut Command) -> std::result::Result<(), String> {
    let out = cmd.output().map_err(|e| format!("cannot start {:?}: {e}", cmd.get_program()))?;
    if out.status.success() {
        Ok(())
    } else {
        let err = String::from_utf8_lossy(&out.stderr);
        Err(err.lines().rfind(|l| l.contains("error")).unwrap_or("failed").trim().to_string())
    }
}

fn check(args: &[String]) -> Result<()> {
    use Takes::{Nothing, Number, Value};
    let known = [
        ("--count", Number),
        ("--seed", Number),
        ("--size", Number),
        ("--spp", Number),
        ("--ingredients", Value),
        ("--release", Nothing),
        ("--hush", Value),
    ];
    let flags = Flags::parse(args, &known, 0, USAGE.trim_start_matches("usage: "))?;
    let count: u64 = flags.number("--count", 100)?;
    let seed: u64 = flags.number("--seed", 0)?;
    let size: u32 = flags.number("--size", 32)?;
    let spp: u32 = flags.number("--spp", 4)?;
    let features = flags.value("--ingredients").unwrap_or("default").to_string();
    ensure_vulkan()?;
    let hush = match flags.value("--hush") {
        Some(path) => PathBuf::from(path),
        None => build_hush(flags.has("--release"))?,
    };
    let dir = target_dir().join("procedural");
    let _ = std::fs::remove_dir_all(dir.join("scenes"));
    let start = Instant::now();
    let mut rows = Vec::new();
    let mut failures = Vec::new();
    for s in seed..seed + count {
        let scene_dir = dir.join(format!("scenes/seed_{s}"));
        let xml = scene_dir.join("scene.xml");
        let summary = scene_dir.join("summary.json");
        let stats = scene_dir.join("stats.json");
        let generated = quiet(
            Command::new(&hush)
                .args(["scene", "generate", "--seed", &s.to_string(), "--ingredients", &features, "--out"])
                .arg(&xml)
                .arg("--summary")
                .arg(&summary),
        );
        let rendered = generated.and_then(|()| {
            quiet(
                Command::new(&hush)
                    .arg("render")
                    .arg(&xml)
                    .args(["--spp", &spp.to_string(), "--width", &size.to_string(), "--height", &size.to_string()])
                    .arg("--out")
                    .arg(scene_dir.join("render.exr"))
                    .arg("--stats")
                    .arg(&stats),
            )
        });
        let row = rendered.and_then(|()| {
            let (summary, stats) = (read_json(&summary)?, read_json(&stats)?);
            let xml = std::fs::read_to_string(&xml).map_err(|e| format!("{}: {e}", xml.display()))?;
            Ok((s, summary, stats, xml))
        });
        match row {
            Ok((s, summary, stats, xml)) => {
                let bad = stats["non_finite_values"].as_u64().unwrap_or(u64::MAX);
                if bad > 0 {
                    failures.push(format!("seed {s}: {bad} non-finite values in the render"));
                }
                eprintln!(
                    "seed {s}: {} style, mean luminance {:.4}, {} non-finite, {} discarded samples",
                    summary["style"].as_str().unwrap_or("?"),
                    stats["mean_luminance"].as_f64().unwrap_or(f64::NAN),
                    bad,
                    stats["discarded_samples"]
                );
                rows.push((s, summary, stats, xml));
            }
            Err(e) => {
                eprintln!("seed {s}: FAILED: {e}");
                failures.push(format!("seed {s}: {e}"));
            }
        }
    }

    // Distinct scenes: no two scene files alike.
    let distinct: BTreeSet<&str> = rows.iter().map(|r| r.3.as_str()).collect();
    if distinct.len() < rows.len() {
        failures.push(format!("only {} distinct scenes among {}", distinct.len(), rows.len()));
    }
    let mut lum: Vec<f64> = rows.iter().filter_map(|r| r.2["mean_luminance"].as_f64()).collect();
    lum.sort_by(f64::total_cmp);
    let mut shapes_of: BTreeMap<String, u64> = BTreeMap::new();
    let mut scenes_with: BTreeMap<String, u64> = BTreeMap::new();
    let mut lights: BTreeMap<String, u64> = BTreeMap::new();
    let mut scenes_lit_by: BTreeMap<String, u64> = BTreeMap::new();
    let mut styles: BTreeMap<String, u64> = BTreeMap::new();
    let mut bsdfs: BTreeMap<String, u64> = BTreeMap::new();
    let mut surfaces = 0;
    for (_, summary, _, _) in &rows {
        for (class, n) in summary["materials"].as_object().into_iter().flatten() {
            let n = n.as_u64().unwrap_or(0);
            *shapes_of.entry(class.clone()).or_default() += n;
            *scenes_with.entry(class.clone()).or_default() += u64::from(n > 0);
            surfaces += n;
        }
        for (kind, n) in summary["bsdfs"].as_object().into_iter().flatten() {
            *bsdfs.entry(kind.clone()).or_default() += n.as_u64().unwrap_or(0);
        }
        let kinds: BTreeSet<&str> =
            summary["lights"].as_array().into_iter().flatten().filter_map(|l| l.as_str()).collect();
        for l in summary["lights"].as_array().into_iter().flatten().filter_map(|l| l.as_str()) {
            *lights.entry(l.to_string()).or_default() += 1;
        }
        for k in kinds {
            *scenes_lit_by.entry(k.to_string()).or_default() += 1;
        }
        *styles.entry(summary["style"].as_str().unwrap_or("?").to_string()).or_default() += 1;
    }
    let n = rows.len().max(1) as f64;
    let share = |m: &BTreeMap<String, u64>, total: f64| -> serde_json::Value {
        m.iter().map(|(k, v)| (k.clone(), serde_json::json!(*v as f64 / total.max(1.0)))).collect()
    };
    let report = serde_json::json!({
        "count": count,
        "seeds": [seed, seed + count - 1],
        "size": size,
        "spp": spp,
        "features": features,
        "rendered": rows.len(),
        "failures": failures,
        "distinct_scenes": distinct.len(),
        "mean_luminance": {
            "min": quantile(&lum, 0.0),
            "p10": quantile(&lum, 0.1),
            "median": quantile(&lum, 0.5),
            "p90": quantile(&lum, 0.9),
            "max": quantile(&lum, 1.0),
        },
        "material_share_of_surfaces": share(&shapes_of, surfaces as f64),
        "scenes_with_material": share(&scenes_with, n),
        "bsdf_counts": bsdfs,
        "light_counts": lights,
        "scenes_with_light": share(&scenes_lit_by, n),
        "styles": styles,
        "seconds": start.elapsed().as_secs_f64(),
    });
    let out = dir.join("summary.json");
    write_json(&out, &report)?;
    eprintln!("{}", serde_json::to_string_pretty(&report).expect("JSON values serialize"));
    eprintln!("→ {}", out.display());
    if !failures.is_empty() {
        return Err(format!("{} of {count} procedural scenes failed (listed in {})", failures.len(), out.display()));
    }
    Ok(())
}
