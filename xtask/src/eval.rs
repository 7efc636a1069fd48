//! `cargo xtask eval`: `hush eval` on the demo's dataset and model (`target/demo/`, made by `cargo xtask
//! demo`; rendered and trained here first if missing) with the noisy input, the trained model and every
//! baseline hush knows (`--baseline all`), into `target/eval/`. `--dataset DIR --model FILE` evaluate another
//! dataset and model instead, `--out DIR` writes elsewhere.
//!
//! `--check-html` then opens `report.html` in headless Chromium (installed with apt-get when missing and
//! run as root) through hush-eval's `html_renders_in_chromium` test, which drives the image comparison with
//! real key, mouse and wheel events (over the DevTools protocol) on synthetic reports whose pixels it knows,
//! and on this report checks that it loads with no request but its own file, no console error, plots with
//! axis titles and legends, a viewer that flips, and a screenshot that is not blank.

use std::path::PathBuf;
use std::process::Command;

use crate::args::{Flags, Takes};
use crate::demo::{self, DemoPaths, eval_command};
use crate::util::{Result, build_hush, cargo, ensure_vulkan, is_root, project_root, spawn, target_dir};

const USAGE: &str =
    "cargo xtask eval [--release] [--check-html] [--timing-runs N] [--dataset DIR --model FILE] [--out DIR]";
const CHROMIUM_INSTALL: &str = "apt-get install -y chromium";

pub fn run(args: &[String]) -> Result<()> {
    use Takes::{Nothing, Number, Value};
    let known = [
        ("--release", Nothing),
        ("--check-html", Nothing),
        ("--timing-runs", Number),
        ("--dataset", Value),
        ("--model", Value),
        ("--out", Value),
    ];
    let flags = Flags::parse(args, &known, 0, USAGE)?;
    let timing_runs = flags.value("--timing-runs").unwrap_or("3").to_string();
    let (dataset, model) = (flags.value("--dataset").map(PathBuf::from), flags.value("--model").map(PathBuf::from));
    let out = flags.value("--out").map_or_else(|| target_dir().join("eval"), PathBuf::from);
    ensure_vulkan()?;
    let hush = build_hush(flags.has("--release"))?;
    let (dataset, model) = match (dataset, model) {
        (Some(dataset), Some(model)) => (dataset, model),
        (None, None) => {
            let paths = DemoPaths::new();
            if !paths.dataset.join("manifest.json").is_file() {
                eprintln!("xtask: no demo dataset in {}; rendering it", paths.dataset.display());
                demo::render_dataset(&hush, &paths)?;
            }
            if !paths.model().is_file() {
                eprintln!("xtask: no demo model at {}; training it", paths.model().display());
                demo::train(&hush, &paths)?;
            }
            (paths.dataset.clone(), paths.model())
        }
        _ => return Err(format!("--dataset and --model go together\nusage: {USAGE}")),
    };
    spawn(eval_command(&hush, &dataset, &model, &out).args(["--baseline", "all", "--timing-runs", &timing_runs]))?;
    let html = out.join("report.html");
    if flags.has("--check-html") {
        check_html(&html)?;
    }
    println!("report: {}", html.display());
    println!("        {}", out.join("report.md").display());
    Ok(())
}

/// Runs hush-eval's Chromium test on `html`, installing Chromium first where it is missing and we may.
fn check_html(html: &std::path::Path) -> Result<()> {
    let has_chromium = has_chromium();
    if !has_chromium {
        if is_root() && std::path::Path::new("/usr/bin/apt-get").exists() {
            eprintln!("xtask: Chromium is missing; installing it: {CHROMIUM_INSTALL}");
            spawn(Command::new("apt-get").args(["update", "-qq"]))?;
            spawn(Command::new("apt-get").args(["install", "-y", "-qq", "chromium"]))?;
        } else {
            return Err(format!("--check-html needs Chromium: install it, e.g. `sudo {CHROMIUM_INSTALL}`"));
        }
    }
    spawn(browser_test().env("HUSH_CHROMIUM_HTML", html))
}

/// Whether Chromium is installed.
pub fn has_chromium() -> bool {
    Command::new("chromium").arg("--version").output().is_ok_and(|o| o.status.success())
}

/// hush-eval's Chromium test (ignored by default) as a cargo command.
pub fn browser_test() -> Command {
    let mut c = Command::new(cargo());
    c.current_dir(project_root()).args(["test", "-p", "hush-eval", "--test", "it", "html_renders_in_chromium"]);
    c.args(["--", "--ignored", "--nocapture"]);
    c
}
