//! `cargo xtask <task>`: orchestration of the `hush` binary. It spawns processes and reads
//! their JSON; it links neither Candle nor wgpu.

mod args;
mod baselines;
mod bench;
mod bench_finetune;
mod bench_net;
mod cuda_check;
mod demo;
mod eval;
mod faults;
mod fuzz;
mod gpu_check;
mod hostile;
mod mitsuba;
mod procedural;
mod soak;
mod sweep;
mod test;
mod train_check;
mod train_default;
mod util;

use std::process::ExitCode;

const USAGE: &str = "usage: cargo xtask <task>
tasks:
  test [cargo test args]     install a Vulkan driver if none is present, then run every test and
                             (without args) every sweep at its tiny scale
  demo [--release] [--resume] render → dataset → train → eval → report on the bundled Cornell box
  eval [--release] [--check-html] [--timing-runs N] [--dataset DIR --model FILE] [--out DIR]
                             hush eval on the demo's dataset and model with every baseline: report,
                             error against run time, pictures in target/eval/ (--check-html: render
                             report.html in headless Chromium)
  train-check [--release] [--resume] [--steps N]
                             train a narrow U-Net on a small dataset of the Cornell box and Veach's MIS
                             scene; fail unless it beats the noisy input by >= 5 dB PSNR on each scene's
                             held-out views at 4 spp (target/train-check/summary.json)
  train-default [--release] [--steps N] [--only hush_alb_nrm|hush_color]
                             retrain the shipped models (resumable): render the dataset of the bundled and
                             procedural scenes, fine-tune OIDN's weights, evaluate against OIDN on the held-out
                             scenes, write data/models/<name>.safetensors, .tza and the model card .md
  bench render [--release] [--spp N] [--repeats N] [--only NAME]
                             M paths per CPU-second and relMSE × CPU-seconds on the Cornell box, veach-mis,
                             living-room, spheres under a sky and three procedural rooms (max_depth 8),
                             hush against Mitsuba 3 when it is installed
  bench dataset [--size N] [--views N] [--procedural N] [--hush PATH]
                             perspectives per hour of `hush dataset` (default settings) on the Cornell box
                             or on N procedural scenes, of this build or of the one at PATH
  bench net [--release]      inference of OIDN's unet_small, unet and unet_large against OIDN 2.5.1 on the same
                             weights and inputs (warm at 512² and 1080p, whole processes at 960², peak memory),
                             a training step's GFLOP/s against the machine's GEMM rate for 1 and 2 threads
  bench train [--release] [--steps N]
                             steps per second, the loader's share and the seconds until the samples are
                             ready (from the f16 cache when it is intact) of `hush train` (a narrow U-Net from scratch)
  bench finetune [--release] [--steps N]
                             held-out PSNR against training seconds on the demo's dataset, from OIDN's weights
                             and from random weights (OIDN's unet, the same steps), and steps per second
  baselines setup            install OIDN 2.5.1, BM3D, flip-evaluator, scikit-image (PyPI) into target/baselines-venv
  baselines check            run BM3D and OIDN through hush-eval on a Cornell box crop; fail unless both help
  procedural check [--count N] [--seed S] [--ingredients default|basic|...]
                             N procedural scenes (default 100) generate and render at 32² without
                             NaN/Inf; spread of mean luminance, material and light mix
  mitsuba setup              install Mitsuba 3 (PyPI) into target/mitsuba-venv and verify it renders
  mitsuba references         re-render the references of data/tests/mitsuba with Mitsuba 3
  fuzz [TARGET ...] [--minutes N] [--max-len BYTES]
                             coverage-guided fuzzing (libFuzzer, stable Rust) of the loaders: mitsuba, obj, gltf,
                             exr, weights, manifest, sweep; N minutes each (default 10); findings and a summary
                             in target/fuzz/ (kept cases in tests/fuzz/regressions/ replay in `cargo test`)
  hostile [--release]        hush against crafted files (huge headers, endless files, loops, deep nesting, a
                             32768² render) under /usr/bin/time and prlimit: each a clear error or a named
                             warning, under 100 MB of peak memory; the table in target/hostile/summary.json
  faults [--release]         (root) the disk filling during a dataset, a training run and a report, and a
                             read-only output folder, on a small tmpfs: a clear error each, then a resume that
                             keeps every complete file; the table in target/faults/summary.json
  soak [--kills N] [--seed S] [--release]
                             dataset → train → the tiny loss sweep, SIGKILLed N times (default 20) at random
                             moments and resumed: every output complete and equal to an uninterrupted run's
  cuda-check                 check that the `cuda` feature compiles (hush, hush-net, hush-train, all targets)
                             with NVIDIA's nvcc from PyPI in target/cuda-venv, into target/cuda-check; no GPU
                             needed (heavy: 10 to 12 minutes cold on 2 cores; run by hand before releases)
  gpu-check                  on a machine with an NVIDIA GPU: build with cuda, check that wgpu renders on the GPU,
                             render, fine-tune and denoise there, each against the CPU path and the GPU peers
                             (Mitsuba 3 cuda_ad_rgb, OIDN's CUDA device); target/gpu-check/gpu-check.json.
                             Elsewhere it stops at once saying that no GPU is present
";

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let result = match args.first().map(String::as_str) {
        Some("demo") => demo::run(&args[1..]),
        Some("bench") => bench::run(&args[1..]),
        Some("eval") => eval::run(&args[1..]),
        Some("test") => test::run(&args[1..]),
        Some("mitsuba") => mitsuba::run(&args[1..]),
        Some("procedural") => procedural::run(&args[1..]),
        Some("baselines") => baselines::run(&args[1..]),
        Some("sweep") => sweep::run(&args[1..]),
        Some("train-check") => train_check::run(&args[1..]),
        Some("train-default") => train_default::run(&args[1..]),
        Some("cuda-check") => cuda_check::run(&args[1..]),
        Some("gpu-check") => gpu_check::run(&args[1..]),
        Some("fuzz") => fuzz::run(&args[1..]),
        Some("hostile") => hostile::run(&args[1..]),
        Some("faults") => faults::run(&args[1..]),
        Some("soak") => soak::run(&args[1..]),
        _ => Err(format!("{USAGE}{}", sweep::USAGE)),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("xtask: {e}");
            ExitCode::FAILURE
        }
    }
}
