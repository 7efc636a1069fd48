//! Mitsuba 3, the peer renderer: `cargo xtask mitsuba setup` installs it from PyPI into a venv
//! under `target/mitsuba-venv`, `cargo xtask mitsuba references` re-renders the references of
//! `data/tests/mitsuba`, and `bench render` uses it as the renderer hush is measured against.
//!
//! Its `llvm_ad_rgb` variant JIT-compiles through libLLVM: the machine's default LLVM 15 crashes
//! it, so it runs with Debian's `libllvm19` (`DRJIT_LIBLLVM_PATH`). Everything Python lives in
//! `xtask/mitsuba_tool.py` and `data/tests/mitsuba/render_references.py`; this file only spawns them.

use std::path::{Path, PathBuf};
use std::process::Command;

use crate::util::{Result, ensure_venv, is_root, project_root, spawn, target_dir, write_atomic};

/// The Mitsuba release hush is measured against (PyPI `mitsuba`; it pins its `drjit`).
pub const VERSION: &str = "3.9.1";
/// The one command that installs it.
pub const SETUP: &str = "cargo xtask mitsuba setup";
/// Debian's LLVM 19 (package `libllvm19`), which the LLVM backend is run with.
const LIBLLVM19: &str = "/usr/lib/x86_64-linux-gnu/libLLVM-19.so";
const LIBLLVM19_FALLBACK: &str = "/usr/lib/x86_64-linux-gnu/libLLVM-19.so.1";

pub fn run(args: &[String]) -> Result<()> {
    match args.first().map(String::as_str) {
        Some("setup") => {
            crate::args::Flags::parse(&args[1..], &[], 0, "cargo xtask mitsuba setup").and_then(|_| setup())
        }
        // Its arguments are render_references.py's.
        Some("references") => references(&args[1..]),
        _ => Err("usage: cargo xtask mitsuba setup | references [render_references.py args]".into()),
    }
}

fn venv_dir() -> PathBuf {
    target_dir().join("mitsuba-venv")
}

fn venv_python() -> PathBuf {
    crate::util::venv_python(&venv_dir())
}

/// Written last by `setup`, after a verified render: its presence means "installed and working".
fn marker() -> PathBuf {
    venv_dir().join(format!("hush-mitsuba-{VERSION}.ok"))
}

/// The folder shared by the project's repositories (`<root>/../shared`), if present.
pub fn shared_dir() -> Option<PathBuf> {
    let dir = project_root().parent()?.join("shared");
    dir.is_dir().then_some(dir)
}

/// The 1792-spp Mitsuba render of the Cornell box, independent of any low-spp render.
pub fn cbox_reference() -> Option<PathBuf> {
    let p = shared_dir()?.join("reference/mitsuba-cbox/mitsuba_1792spp.exr");
    p.is_file().then_some(p)
}

/// The libLLVM the LLVM backend is run with: `DRJIT_LIBLLVM_PATH` if set, else Debian's LLVM 19.
fn libllvm() -> Option<PathBuf> {
    if let Some(p) = std::env::var_os("DRJIT_LIBLLVM_PATH") {
        return Some(PathBuf::from(p));
    }
    [LIBLLVM19, LIBLLVM19_FALLBACK].iter().map(PathBuf::from).find(|p| p.exists())
}

/// Whether `setup` has completed (a render was verified).
pub fn installed() -> bool {
    marker().is_file() && venv_python().is_file() && libllvm().is_some()
}

/// The venv's Python, with the environment Mitsuba's LLVM backend needs. Fails with the command
/// that installs it when `setup` has not run.
pub fn python() -> Result<Command> {
    if !installed() {
        return Err(format!("Mitsuba {VERSION} is not installed: run `{SETUP}`"));
    }
    let mut cmd = Command::new(venv_python());
    cmd.env("DRJIT_LIBLLVM_PATH", libllvm().expect("installed() checked it")).env("PYTHONUNBUFFERED", "1");
    Ok(cmd)
}

/// `xtask/mitsuba_tool.py`: the helper (check, bench, relmse) run in the venv.
pub fn helper() -> PathBuf {
    project_root().join("xtask").join("mitsuba_tool.py")
}

fn ensure_libllvm19() -> Result<()> {
    if let Some(p) = libllvm() {
        if p.exists() {
            return Ok(());
        }
        return Err(format!("DRJIT_LIBLLVM_PATH={} does not exist", p.display()));
    }
    const INSTALL: &str = "apt-get install -y libllvm19";
    if is_root() && Path::new("/usr/bin/apt-get").exists() {
        eprintln!("xtask: Mitsuba's LLVM backend needs LLVM 19 (the default LLVM 15 crashes it): {INSTALL}");
        spawn(Command::new("apt-get").args(["update", "-qq"]))?;
        spawn(Command::new("apt-get").args(["install", "-y", "-qq", "libllvm19"]))?;
        return match libllvm() {
            Some(_) => Ok(()),
            None => Err(format!("`{INSTALL}` ran but {LIBLLVM19} is still missing")),
        };
    }
    Err(format!(
        "Mitsuba's LLVM backend needs LLVM 19 (the default LLVM 15 crashes it): run `sudo {INSTALL}` \
         (or set DRJIT_LIBLLVM_PATH to a libLLVM 19), then `{SETUP}`"
    ))
}

/// Installs Mitsuba from PyPI into `target/mitsuba-venv` and renders the Cornell box with it.
fn setup() -> Result<()> {
    ensure_libllvm19()?;
    let dir = venv_dir();
    ensure_venv(&dir, "3.8+")?;
    spawn(Command::new(venv_python()).args([
        "-m",
        "pip",
        "install",
        "--quiet",
        &format!("mitsuba=={VERSION}"),
        "numpy>=1.24,<3",
    ]))?;
    // Verify: render the Cornell box (the shared one, whose 1792-spp render the check compares
    // with, else the bundled copy) at 16 spp.
    let (scene, reference) = match (shared_dir(), cbox_reference()) {
        (Some(shared), Some(reference)) => (shared.join("reference/mitsuba-cbox/scene.xml"), Some(reference)),
        _ => (project_root().join("data/scenes/cbox/scene.xml"), None),
    };
    let mut cmd = Command::new(venv_python());
    cmd.env("DRJIT_LIBLLVM_PATH", libllvm().expect("ensured above"))
        .arg(helper())
        .arg("check")
        .arg("--scene")
        .arg(&scene)
        .args(["--spp", "16"])
        .arg("--out")
        .arg(target_dir().join("mitsuba-check.exr"));
    if let Some(r) = &reference {
        cmd.arg("--ref").arg(r);
    }
    spawn(&mut cmd)?;
    write_atomic(&marker(), &format!("mitsuba {VERSION}\n"))?;
    println!("Mitsuba {VERSION} (llvm_ad_rgb) installed in {} and verified", dir.display());
    Ok(())
}

/// Re-renders every reference of `data/tests/mitsuba` (slow: minutes per scene).
fn references(args: &[String]) -> Result<()> {
    let script = project_root().join("data/tests/mitsuba/render_references.py");
    spawn(python()?.arg(script).args(args))
}
