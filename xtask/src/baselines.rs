//! The Python baselines of `hush eval`: `cargo xtask baselines setup` installs official OIDN 2.5.1 (PyPI
//! `pyoidn`), BM3D, flip-evaluator and scikit-image (the versions pinned in
//! `crates/hush-eval/baselines/requirements.txt`) into a venv under `target/baselines-venv`, and
//! `cargo xtask baselines check` runs BM3D and OIDN through hush-eval on a 64² crop of the Cornell box and
//! checks that they lower its error (the test `external::run_for_real_when_installed`, required to run), that
//! OIDN's runtime runs weights written as hush writes them (`hush export`) as hush does
//! (`external::oidn_runtime_runs_other_weights_as_hush_does`, ≥ 45 dB), then that hush-eval's `oidn` feature, built against pyoidn's bundled library, reproduces OIDN's outputs.

use std::path::PathBuf;
use std::process::Command;

use crate::util::{Result, ensure_venv, project_root, site_packages, spawn, target_dir};

/// The one command that installs the baselines (also printed by hush-eval when one is missing).
pub const SETUP: &str = "cargo xtask baselines setup";

pub fn run(args: &[String]) -> Result<()> {
    // Neither takes a flag.
    crate::args::Flags::parse(args.get(1..).unwrap_or_default(), &[], 0, "cargo xtask baselines setup | check")?;
    match args.first().map(String::as_str) {
        Some("setup") => setup(),
        Some("check") => check(),
        _ => Err("usage: cargo xtask baselines setup | check".into()),
    }
}

fn venv_dir() -> PathBuf {
    target_dir().join("baselines-venv")
}

/// The venv's Python, whether or not it is installed yet.
pub fn venv_python() -> PathBuf {
    crate::util::venv_python(&venv_dir())
}

fn requirements() -> PathBuf {
    project_root().join("crates/hush-eval/baselines/requirements.txt")
}

/// Creates the venv (if needed), installs the pinned packages and checks that they import.
fn setup() -> Result<()> {
    let dir = venv_dir();
    ensure_venv(&dir, "3.9+")?;
    spawn(Command::new(venv_python()).args(["-m", "pip", "install", "--quiet", "-r"]).arg(requirements()))?;
    spawn(Command::new(venv_python()).args([
        "-c",
        "import importlib.metadata as m, bm3d, pyoidn, flip_evaluator, skimage, numpy; \
         print('baselines:', *(p + ' ' + m.version(p) for p in \
         ['pyoidn', 'bm3d', 'flip-evaluator', 'scikit-image', 'numpy']))",
    ]))?;
    println!("Python baselines installed in {} (pinned in {})", dir.display(), requirements().display());
    Ok(())
}

/// Runs BM3D and OIDN for real through hush-eval and fails if either is skipped or does not help; then
/// builds hush-eval's `oidn` feature against pyoidn's bundled library and checks that in-process OIDN
/// reproduces OIDN 2.5.1's shared outputs.
fn check() -> Result<()> {
    if !venv_python().is_file() {
        return Err(format!("the baselines are not installed ({} is missing): run `{SETUP}`", venv_python().display()));
    }
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let test = |features: &[&str], filter: &str| {
        let mut cmd = Command::new(&cargo);
        cmd.current_dir(project_root()).args(["test", "-p", "hush-eval"]).args(features);
        cmd.args(["--test", "it", filter, "--", "--nocapture"]);
        cmd
    };
    for filter in ["external::run_for_real_when_installed", "external::oidn_runtime_runs_other_weights_as_hush_does"] {
        spawn(test(&[], filter).env("HUSH_REQUIRE_BASELINES", "1").env("HUSH_BASELINES_PYTHON", venv_python()))?;
    }
    let oidn_dir = oidn_dir()?;
    spawn(
        test(&["--features", "oidn"], "external::oidn_native")
            .env("LD_LIBRARY_PATH", oidn_dir.join("lib"))
            .env("OIDN_DIR", &oidn_dir),
    )
}

/// `<venv>/lib/python3.*/site-packages/pyoidn/oidn`: OIDN's library as bundled by pyoidn.
pub fn oidn_dir() -> Result<PathBuf> {
    let dir = site_packages(&venv_dir()).map_err(|e| format!("{e}: run `{SETUP}`"))?.join("pyoidn/oidn");
    if !dir.join("lib").is_dir() {
        return Err(format!("pyoidn's bundled OIDN not found in {}: run `{SETUP}`", dir.display()));
    }
    Ok(dir)
}
