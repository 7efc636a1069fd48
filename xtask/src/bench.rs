//! `cargo xtask bench render`: M paths per CPU-second of hush on the Cornell box.

use std::process::Command;

use crate::util::{Result, build_hush, ensure_vulkan, project_root, read_json, release, spawn, target_dir, write_json};

pub fn run(args: &[String]) -> Result<()> {
    match args.first().map(String::as_str) {
        Some("render") => render(&args[1..]),
        _ => Err("usage: cargo xtask bench render [--release] [--spp N]".into()),
    }
}

fn spp_arg(args: &[String], default: u32) -> Result<u32> {
    match args.iter().position(|a| a == "--spp") {
        Some(i) => args.get(i + 1).and_then(|s| s.parse().ok()).ok_or_else(|| "--spp needs a number".to_string()),
        None => Ok(default),
    }
}

/// The box at 512², max_depth 8. CPU-seconds count every thread of the process, so the figure
/// compares with peers measured the same way on the same machine.
fn render(args: &[String]) -> Result<()> {
    ensure_vulkan()?;
    let hush = build_hush(release(args))?;
    let spp = spp_arg(args, 16)?;
    let dir = target_dir().join("bench");
    let scene = project_root().join("data/scenes/cbox/scene.xml");
    let stats = dir.join("render-hush-cbox.json");
    std::fs::create_dir_all(&dir).map_err(|e| e.to_string())?;
    spawn(
        Command::new(&hush)
            .args(["render"])
            .arg(&scene)
            .args(["--spp", &spp.to_string(), "--width", "512", "--height", "512", "--max-depth", "8", "--out"])
            .arg(dir.join("render-cbox.exr"))
            .arg("--stats")
            .arg(&stats),
    )?;
    let s = read_json(&stats)?;
    let result = serde_json::json!({
        "benchmark": "render",
        "scene": "cbox (Mitsuba 3 Cornell box)",
        "width": 512, "height": 512, "max_depth": 8, "spp": spp,
        "hush": {
            "mpaths_per_cpu_second": s["mpaths_per_cpu_second"],
            "mpaths_per_second": s["mpaths_per_second"],
            "cpu_seconds": s["cpu_seconds"],
            "wall_seconds": s["wall_seconds"],
            "adapter": s["adapter"],
        },
    });
    let out = dir.join("render.json");
    write_json(&out, &result)?;
    println!("{}", serde_json::to_string_pretty(&result).expect("serializes"));
    println!("written to {}", out.display());
    Ok(())
}
