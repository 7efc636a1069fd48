//! `cargo xtask gpu-check`: on a machine with an NVIDIA GPU, the whole pipeline on it, each stage against
//! the CPU path and against the GPU peers, in one JSON (`target/gpu-check/gpu-check.json`).
//!
//! 1. `nvidia-smi` names the GPU; without one the task stops at once with one line saying so.
//! 2. hush is built with `--features cuda` (`--release`, into `target/gpu-check/build` so that the normal
//!    builds' caches stay valid), with the machine's `nvcc` or else NVIDIA's from PyPI (as `cuda-check`),
//!    for the GPU's compute capability.
//! 3. Render: the Cornell box, spheres under a sky and a procedural room (max_depth 8) through wgpu with
//!    Vulkan and no driver override; the adapter must be a GPU (never lavapipe, which would make every
//!    figure a CPU one). Each against lavapipe on the same scene at fewer spp (the CPU path, M paths per
//!    wall second) and against Mitsuba 3's `cuda_ad_rgb` variant on the same XML where Mitsuba is
//!    installed (`cargo xtask mitsuba setup`).
//! 4. Train: a small dataset of the box rendered on the GPU, `hush train --device cuda` fine-tuning OIDN's
//!    weights a few steps (the loss must stay finite), and one training step (OIDN's `unet`, batch 4,
//!    128², color + albedo + normal) on the GPU against the CPU, warm (`hush bench train-step`).
//! 5. Denoise: `hush denoise --device cuda` of the GPU's 512² box render, and OIDN's `unet` with its
//!    official weights at 512² and 1080p, warm (`hush bench inference --weights`), on the GPU against the
//!    CPU and against OIDN 2.5.1's CUDA device (`oidnDenoise -d cuda`, same weights and inputs) where the
//!    baselines are installed (`cargo xtask baselines setup`) and their OIDN has that device.
//!
//! It is meant to take under 10 minutes with a warm build folder; the JSON records each stage's seconds.
//! A peer that is missing is recorded as skipped with the command that installs it; a stage that fails
//! stops the check with its error.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use crate::bench::ratio;
use crate::bench_net::{helper, hush_json, median, oidn_warm_seconds};
use crate::util::{Result, cargo, load_average, project_root, read_json, spawn, target_dir, write_json};
use crate::{baselines, mitsuba};

const USAGE: &str = "cargo xtask gpu-check";
/// lavapipe's ICD, the CPU path of the render comparison.
const LAVAPIPE_ICD: &str = "/usr/share/vulkan/icd.d/lvp_icd.x86_64.json";

/// The GPU `nvidia-smi` reports first.
#[derive(Debug, PartialEq)]
struct Gpu {
    name: String,
    memory: String,
    compute_cap: String,
    driver: String,
}

/// Parses `nvidia-smi --query-gpu=name,memory.total,compute_cap,driver_version --format=csv,noheader`.
fn parse_gpus(text: &str) -> Vec<Gpu> {
    text.lines()
        .filter_map(|line| {
            let f: Vec<&str> = line.split(',').map(str::trim).collect();
            (f.len() == 4 && !f[0].is_empty()).then(|| Gpu {
                name: f[0].into(),
                memory: f[1].into(),
                compute_cap: f[2].into(),
                driver: f[3].into(),
            })
        })
        .collect()
}

/// The machine's first NVIDIA GPU, or the one line that says there is none.
fn find_gpu() -> Result<Gpu> {
    let none = |why: String| {
        format!("gpu-check: no NVIDIA GPU on this machine ({why}); run it where one is (README, \"GPUs\")")
    };
    let out = Command::new("nvidia-smi")
        .args(["--query-gpu=name,memory.total,compute_cap,driver_version", "--format=csv,noheader"])
        .output()
        .map_err(|e| none(format!("nvidia-smi: {e}")))?;
    if !out.status.success() {
        return Err(none(format!("nvidia-smi failed ({})", out.status)));
    }
    parse_gpus(&String::from_utf8_lossy(&out.stdout))
        .into_iter()
        .next()
        .ok_or_else(|| none("nvidia-smi lists none".into()))
}

/// The compute capability (`8.0` or `80`) to build CUDA kernels for: `CUDA_COMPUTE_CAP` where set, else the
/// first GPU's; none on a machine without either (a cluster's login node: set the variable there).
pub fn compute_cap() -> Result<String> {
    if let Ok(cap) = std::env::var("CUDA_COMPUTE_CAP") {
        return Ok(cap);
    }
    find_gpu().map(|gpu| gpu.compute_cap).map_err(|_| {
        "no NVIDIA GPU here to build CUDA kernels for: set CUDA_COMPUTE_CAP to the GPUs' compute capability (80 for \
         an A100, 90 for an H100)"
            .to_string()
    })
}

/// hush built `--release --features cuda` for `compute_cap` into `target/gpu-check/build` (the normal
/// builds' caches stay valid): the machine's nvcc where it has one, else NVIDIA's wheels.
pub fn build_cuda(compute_cap: &str) -> Result<PathBuf> {
    let compute_cap = compute_cap.replace('.', "");
    let dir = target_dir().join("gpu-check").join("build");
    let mut cmd = Command::new(cargo());
    cmd.current_dir(project_root()).args(["build", "--release", "--package", "hush", "--features", "cuda"]);
    cmd.env("CARGO_TARGET_DIR", &dir).env("CUDA_COMPUTE_CAP", &compute_cap);
    let has_nvcc = Command::new("nvcc").arg("--version").output().is_ok_and(|o| o.status.success());
    if !has_nvcc {
        let root = crate::cuda_check::ensure_toolkit()?;
        let path = std::env::var_os("PATH").unwrap_or_default();
        let path = std::env::join_paths(std::iter::once(root.join("bin")).chain(std::env::split_paths(&path)))
            .map_err(|e| format!("{}: cannot be put on PATH: {e}", root.display()))?;
        cmd.env("PATH", path).env("NVCC", root.join("bin").join("nvcc"));
        for var in ["CUDA_HOME", "CUDA_PATH", "CUDA_ROOT"] {
            cmd.env(var, &root);
        }
    }
    spawn(&mut cmd)?;
    Ok(dir.join("release").join("hush"))
}

/// A scene of the render comparison: name, file, size and spp on the GPU (the CPU path renders 1/16 of
/// the spp).
struct Scene {
    name: &'static str,
    file: PathBuf,
    width: u32,
    height: u32,
    spp: u32,
}

/// `hush render` of `scene` at `spp` with its stats; `lavapipe` picks the CPU driver, else the
/// Vulkan loader's default (the GPU's) with any override removed.
fn render(hush: &Path, scene: &Scene, spp: u32, lavapipe: bool, out: &Path) -> Result<serde_json::Value> {
    let stats = out.with_extension("json");
    let mut cmd = Command::new(hush);
    cmd.arg("render").arg(&scene.file).args(["--width", &scene.width.to_string()]);
    cmd.args(["--height", &scene.height.to_string(), "--spp", &spp.to_string(), "--max-depth", "8"]);
    cmd.arg("--warm-up").arg("--out").arg(out).arg("--stats").arg(&stats);
    cmd.env("WGPU_BACKEND", "vulkan").env_remove("VK_ICD_FILENAMES").env_remove("HUSH_ADAPTER");
    if lavapipe {
        cmd.env("VK_DRIVER_FILES", LAVAPIPE_ICD);
    } else {
        cmd.env_remove("VK_DRIVER_FILES");
    }
    spawn(&mut cmd)?;
    read_json(&stats)
}

/// Whether an adapter as `hush render --stats` describes it (`name (driver) [Vulkan, DiscreteGpu]`) is a
/// CPU implementation.
fn is_cpu_adapter(adapter: &str) -> bool {
    adapter.trim_end().ends_with("Cpu]")
}

fn render_stage(hush: &Path, dir: &Path) -> Result<serde_json::Value> {
    let generated = dir.join("procedural-1").join("scene.xml");
    spawn(Command::new(hush).args(["scene", "generate", "--seed", "1", "--out"]).arg(&generated))?;
    let root = project_root();
    let scenes = [
        Scene { name: "cbox", file: root.join("data/scenes/cbox/scene.xml"), width: 512, height: 512, spp: 256 },
        Scene {
            name: "spheres-sky",
            file: root.join("data/tests/mitsuba/spheres-sky/scene.xml"),
            width: 512,
            height: 384,
            spp: 256,
        },
        Scene { name: "procedural-1", file: generated, width: 512, height: 512, spp: 64 },
    ];
    let mut rows = Vec::new();
    for scene in &scenes {
        let gpu = render(hush, scene, scene.spp, false, &dir.join(format!("{}-gpu.exr", scene.name)))?;
        let adapter = gpu["adapter"].as_str().unwrap_or_default().to_string();
        if is_cpu_adapter(&adapter) {
            return Err(format!(
                "gpu-check: wgpu's Vulkan adapter is a CPU one ({adapter}), so no render ran on the GPU: install \
                 the NVIDIA Vulkan driver (its ICD, nvidia_icd.json, under /usr/share/vulkan/icd.d) and run again"
            ));
        }
        let cpu_spp = (scene.spp / 16).max(1);
        let cpu = if Path::new(LAVAPIPE_ICD).is_file() {
            render(hush, scene, cpu_spp, true, &dir.join(format!("{}-lavapipe.exr", scene.name)))?
        } else {
            serde_json::json!({ "skipped": "lavapipe is not installed (apt-get install -y mesa-vulkan-drivers)" })
        };
        let mitsuba_row = match mitsuba::python() {
            Err(e) => serde_json::json!({ "skipped": e, "install": mitsuba::SETUP }),
            Ok(mut py) => {
                let stats = dir.join(format!("{}-mitsuba.json", scene.name));
                py.arg(mitsuba::helper()).arg("bench").arg("--scene").arg(&scene.file);
                py.args(["--spp", &scene.spp.to_string(), "--width", &scene.width.to_string()]);
                py.args(["--height", &scene.height.to_string(), "--max-depth", "8", "--variant", "cuda_ad_rgb"]);
                py.arg("--out").arg(dir.join(format!("{}-mitsuba.exr", scene.name))).arg("--stats").arg(&stats);
                py.stdout(std::process::Stdio::null());
                match spawn(&mut py) {
                    Ok(()) => read_json(&stats)?,
                    Err(e) => serde_json::json!({ "skipped": format!("Mitsuba's cuda_ad_rgb did not run: {e}") }),
                }
            }
        };
        rows.push(serde_json::json!({
            "scene": scene.name, "width": scene.width, "height": scene.height, "max_depth": 8,
            "gpu": { "spp": scene.spp, "adapter": adapter, "mpaths_per_second": gpu["mpaths_per_second"],
                     "wall_seconds": gpu["wall_seconds"], "non_finite_values": gpu["non_finite_values"] },
            "cpu_lavapipe": { "spp": cpu_spp, "adapter": cpu["adapter"], "mpaths_per_second": cpu["mpaths_per_second"],
                              "skipped": cpu["skipped"] },
            "mitsuba_cuda_ad_rgb": mitsuba_row,
            "gpu_over_cpu_mpaths_per_second": ratio(&gpu["mpaths_per_second"], &cpu["mpaths_per_second"]),
            "hush_over_mitsuba_mpaths_per_second":
                ratio(&gpu["mpaths_per_second"], &mitsuba_row["msamples_per_second"]),
        }));
    }
    Ok(serde_json::json!({
        "note": "M paths per wall second (a GPU's CPU-seconds say nothing of its speed); hush's timed render is its \
                 second in the process, Mitsuba's too",
        "scenes": rows,
    }))
}

fn train_stage(hush: &Path, dir: &Path) -> Result<serde_json::Value> {
    let dataset = dir.join("dataset");
    let mut cmd = Command::new(hush);
    cmd.arg("dataset").arg(project_root().join("data/scenes/cbox/scene.xml")).arg("--out").arg(&dataset);
    cmd.args(["--views", "3", "--test-views", "1", "--split-views", "--size", "128", "--spp", "4,16,64"]);
    cmd.args(["--ref-spp", "256", "--aux-spp", "32", "--seed", "1"]);
    cmd.env("WGPU_BACKEND", "vulkan").env_remove("VK_DRIVER_FILES").env_remove("VK_ICD_FILENAMES");
    spawn(&mut cmd)?;
    let run = dir.join("finetune");
    let _ = std::fs::remove_dir_all(&run);
    let mut cmd = Command::new(hush);
    cmd.arg("train").arg("--dataset").arg(&dataset).arg("--out").arg(&run);
    cmd.args(["--device", "cuda", "--init", "oidn", "--steps", "40", "--batch", "4", "--crop", "128"]);
    cmd.args(["--loss", "log_mse", "--loss-space", "tonemapped", "--lr", "3e-5", "--eval-every", "5"]);
    spawn(&mut cmd)?;
    let summary = read_json(&run.join("summary.json"))?;
    let finite = |v: &serde_json::Value| v.as_f64().is_some_and(f64::is_finite);
    if !finite(&summary["best"]["test_loss"]) {
        return Err(format!("gpu-check: the CUDA fine-tuning's test loss is not finite: {}", summary["best"]));
    }
    let step = |device: &str, runs: &str| {
        let args = ["--device", device, "train-step", "--kind", "unet", "--features", "alb,nrm"];
        hush_json(hush, None, &[&args[..], &["--size", "128", "--batch", "4", "--runs", runs]].concat())
    };
    let (gpu, cpu) = (step("cuda", "10")?, step("cpu", "2")?);
    Ok(serde_json::json!({
        "finetune": { "command": "hush train --device cuda --init oidn --steps 40 (128² crops of the box, batch 4)",
                      "steps_per_second": summary["steps_per_second"], "seconds": summary["seconds"],
                      "best": summary["best"], "initial_test_loss": summary["initial_test_loss"] },
        "train_step": { "setting": "OIDN's unet, color + albedo + normal, batch 4, 128², warm median",
                        "gpu": gpu, "cpu": cpu, "cpu_over_gpu_seconds": ratio(&cpu["seconds"], &gpu["seconds"]) },
    }))
}

fn denoise_stage(hush: &Path, dir: &Path) -> Result<serde_json::Value> {
    // The GPU's box render carries its albedo and normal as layers.
    let color = dir.join("cbox-gpu.exr");
    let out = dir.join("cbox-denoised.exr");
    spawn(Command::new(hush).args(["denoise", "--device", "cuda", "--color"]).arg(&color).arg("--out").arg(&out))?;
    let weights = project_root().join("data/weights/oidn-2.5.1/rt_hdr_alb_nrm.tza");
    let weights_arg = weights.to_string_lossy().into_owned();
    let mut rows = Vec::new();
    for (w, h) in [(512usize, 512usize), (1920, 1080)] {
        let bench = |device: &str, runs: &str| {
            let args = ["--device", device, "inference", "--weights", &weights_arg, "--runs", runs];
            hush_json(hush, None, &[&args[..], &["--size", &w.to_string(), "--height", &h.to_string()]].concat())
        };
        let (gpu, cpu) = (bench("cuda", "20")?, bench("cpu", "3")?);
        let oidn = oidn_cuda(&weights, dir, w, h)?;
        rows.push(serde_json::json!({
            "width": w, "height": h, "weights": "rt_hdr_alb_nrm.tza (OIDN's unet)",
            "hush_gpu_seconds": gpu["seconds"], "hush_cpu_seconds": cpu["seconds"], "oidn_cuda": oidn,
            "cpu_over_gpu_seconds": ratio(&cpu["seconds"], &gpu["seconds"]),
            "hush_over_oidn_cuda_seconds": ratio(&gpu["seconds"], &oidn["seconds"]),
        }));
    }
    Ok(serde_json::json!({
        "denoised_render": out.display().to_string(),
        "note": "warm medians: hush's Denoiser kept between executions, OIDN one filter executed repeatedly (-n)",
        "inference": rows,
    }))
}

/// OIDN 2.5.1's CUDA device on the same weights (`oidnDenoise -d cuda -n`), warm median; skipped where the
/// baselines are not installed or their OIDN has no CUDA device.
fn oidn_cuda(weights: &Path, dir: &Path, w: usize, h: usize) -> Result<serde_json::Value> {
    let python = baselines::venv_python();
    let oidn = match baselines::oidn_dir() {
        Ok(dir) if python.is_file() => dir,
        _ => {
            return Ok(serde_json::json!({ "skipped": "OIDN's tools are not installed", "install": baselines::SETUP }));
        }
    };
    let ld_path = oidn.join("lib").display().to_string();
    let inputs = dir.join(format!("inputs-{w}x{h}"));
    std::fs::create_dir_all(&inputs).map_err(|e| format!("{}: {e}", inputs.display()))?;
    let p = |path: &Path| path.to_string_lossy().into_owned();
    helper(&python, &ld_path, &["inputs", &p(&inputs), &w.to_string(), &h.to_string()])?;
    let mut cmd = vec!["run".to_string(), p(&oidn.join("bin/oidnDenoise")), "-d".into(), "cuda".into()];
    cmd.extend(["-w".into(), p(weights)]);
    for (flag, name) in [("--hdr", "color"), ("--alb", "albedo"), ("--nrm", "normal")] {
        cmd.extend([flag.to_string(), p(&inputs.join(format!("{name}.pfm")))]);
    }
    cmd.extend(["-o".into(), p(&inputs.join("oidn-out.pfm")), "-n".into(), "21".into(), "-v".into(), "2".into()]);
    let args: Vec<&str> = cmd.iter().map(String::as_str).collect();
    Ok(match helper(&python, &ld_path, &args) {
        Ok(row) => {
            let times = oidn_warm_seconds(row["output"].as_str().unwrap_or_default());
            serde_json::json!({ "seconds": median(&times), "runs_seconds": times })
        }
        Err(e) => serde_json::json!({ "skipped": format!("OIDN's CUDA device did not run: {e}") }),
    })
}

pub fn run(args: &[String]) -> Result<()> {
    crate::args::Flags::parse(args, &[], 0, USAGE)?;
    let gpu = find_gpu()?;
    let start = Instant::now();
    let dir = target_dir().join("gpu-check");
    std::fs::create_dir_all(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let hush = build_cuda(&gpu.compute_cap)?;
    let build_seconds = start.elapsed().as_secs_f64();
    let mut stages = serde_json::Map::new();
    for (name, stage) in [
        ("render", render_stage as fn(&Path, &Path) -> Result<serde_json::Value>),
        ("train", train_stage),
        ("denoise", denoise_stage),
    ] {
        let t = Instant::now();
        let mut row = stage(&hush, &dir)?;
        row["seconds"] = serde_json::json!(t.elapsed().as_secs_f64());
        stages.insert(name.into(), row);
    }
    let result = serde_json::json!({
        "benchmark": "gpu-check",
        "gpu": { "name": gpu.name, "memory": gpu.memory, "compute_cap": gpu.compute_cap, "driver": gpu.driver },
        "hush": hush.display().to_string(),
        "build_seconds": build_seconds,
        "stages": stages,
        "total_seconds": start.elapsed().as_secs_f64(),
        "load_average": load_average(),
    });
    let out = dir.join("gpu-check.json");
    write_json(&out, &result)?;
    println!(
        "gpu-check: ok on {} in {:.0} s (build {:.0} s) → {}",
        gpu.name,
        start.elapsed().as_secs_f64(),
        build_seconds,
        out.display()
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nvidia_smi_lines_and_adapters_are_read() {
        let text = "NVIDIA H100 80GB HBM3, 81559 MiB, 9.0, 550.54.15\n\n";
        let gpus = parse_gpus(text);
        assert_eq!(gpus.len(), 1);
        assert_eq!((gpus[0].name.as_str(), gpus[0].compute_cap.as_str()), ("NVIDIA H100 80GB HBM3", "9.0"));
        assert!(parse_gpus("No devices were found\n").is_empty());
        assert!(is_cpu_adapter("llvmpipe (LLVM 15.0.6, 256 bits) (llvmpipe Mesa 22.3.6) [Vulkan, Cpu]"));
        assert!(!is_cpu_adapter("NVIDIA H100 (NVIDIA 550.54.15) [Vulkan, DiscreteGpu]"));
    }
}
