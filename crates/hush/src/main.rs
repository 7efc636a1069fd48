//! `hush`: render scenes, build datasets, train denoisers, denoise images and evaluate them. A thin shell over
//! hush-pipeline: each `*_cmd.rs` turns its arguments into a plan, runs it and prints what it did.

mod bench_cmd;
mod blend_cmd;
mod cli;
mod dataset_cmd;
mod denoise_cmd;
mod eval_cmd;
mod export_cmd;
mod progress;
mod render_cmd;
mod report_cmd;
mod scene_cmd;
mod train_cmd;

use clap::Parser;
use hush_trace::GpuContext;

/// Opens the GPU and says which adapter it is, so a fallback is never silent.
fn open_gpu() -> anyhow::Result<GpuContext> {
    let gpu = GpuContext::new()?;
    eprintln!("adapter: {}", gpu.describe());
    Ok(gpu)
}

/// Turns off Mesa's device-selection layer, an implicit Vulkan layer that asks the window system for the
/// default GPU: on a machine without a display, libwayland then prints "error: XDG_RUNTIME_DIR is invalid or
/// not set in the environment." twice, which reads as a failure. hush never draws to a window and picks its
/// adapter itself (`HUSH_ADAPTER`), so the layer has nothing to do. Left alone when the user set
/// `NODEVICE_SELECT` or chose a device through the layer (`MESA_VK_DEVICE_SELECT`).
#[allow(unsafe_code)]
fn quiet_device_select_layer() {
    if std::env::var_os("NODEVICE_SELECT").is_none() && std::env::var_os("MESA_VK_DEVICE_SELECT").is_none() {
        // SAFETY: called first thing in main, before any other thread exists, so nothing reads the
        // environment concurrently.
        unsafe { std::env::set_var("NODEVICE_SELECT", "1") };
    }
}

fn main() {
    quiet_device_select_layer();
    hush_pipeline::process::keep_freed_memory();
    let cli = cli::Cli::parse();
    let result = match cli.command {
        cli::Command::Render(args) => render_cmd::run(args),
        cli::Command::Dataset(args) => dataset_cmd::run(args),
        cli::Command::Scene(args) => scene_cmd::run(args),
        cli::Command::Train(args) => train_cmd::run(args),
        cli::Command::Denoise(args) => denoise_cmd::run(args),
        cli::Command::Export(args) => export_cmd::run(args),
        cli::Command::Blend(args) => blend_cmd::run(args),
        cli::Command::Eval(args) => eval_cmd::run(args),
        cli::Command::Bench(args) => bench_cmd::run(args),
        cli::Command::SweepReport(args) => report_cmd::run(args),
    };
    if let Err(e) = result {
        eprintln!("error: {}", error_text(&e));
        std::process::exit(1);
    }
}

/// The error and its causes joined by ": ", leaving out a cause whose text the message already holds (an
/// error that prints its source itself would otherwise show it twice).
fn error_text(e: &anyhow::Error) -> String {
    let mut text = String::new();
    for cause in e.chain() {
        let part = cause.to_string();
        if text.contains(&part) {
            continue;
        }
        if !text.is_empty() {
            text.push_str(": ");
        }
        text.push_str(&part);
    }
    text
}
