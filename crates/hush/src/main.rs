//! `hush`: render scenes, build datasets, train denoisers, denoise images and evaluate them.

mod bench_cmd;
mod cli;
mod cpu;
mod dataset_cmd;
mod denoise_cmd;
mod denoiser;
mod eval_cmd;
mod render_cmd;
mod report_cmd;
mod scene_cmd;
mod train_cmd;

use clap::Parser;

fn main() {
    cpu::keep_freed_memory();
    let cli = cli::Cli::parse();
    let result = match cli.command {
        cli::Command::Render(args) => render_cmd::run(args),
        cli::Command::Dataset(args) => dataset_cmd::run(args),
        cli::Command::Scene(args) => scene_cmd::run(args),
        cli::Command::Train(args) => train_cmd::run(args),
        cli::Command::Denoise(args) => denoise_cmd::run(args),
        cli::Command::Eval(args) => eval_cmd::run(args),
        cli::Command::Bench(args) => bench_cmd::run(args),
        cli::Command::SweepReport(args) => report_cmd::run(args),
    };
    if let Err(e) = result {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}
