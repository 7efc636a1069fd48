//! `cargo xtask <task>`: orchestration of the `hush` binary. It spawns processes and reads
//! their JSON; it links neither Candle nor wgpu.

mod bench;
mod demo;
mod test;
mod util;

use std::process::ExitCode;

const USAGE: &str = "usage: cargo xtask <task>
tasks:
  test [cargo test args]     install a Vulkan driver if none is present, then run every test
  demo [--release]           render → dataset → train → eval → report on the bundled Cornell box
  bench render [--release]   M paths per CPU-second on the Cornell box, 512², max_depth 8";

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let result = match args.first().map(String::as_str) {
        Some("demo") => demo::run(&args[1..]),
        Some("bench") => bench::run(&args[1..]),
        Some("test") => test::run(&args[1..]),
        _ => Err(USAGE.to_string()),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("xtask: {e}");
            ExitCode::FAILURE
        }
    }
}
