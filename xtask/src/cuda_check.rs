//! `cargo xtask cuda-check`: proves that the `cuda` feature of `hush`, `hush-net` and `hush-train` compiles,
//! on a machine with neither a GPU nor a CUDA toolkit.
//!
//! candle's CUDA backend needs `nvcc` at build time: candle-kernels' build script compiles its kernels to
//! PTX and a static library, and cudarc's asks `nvcc --version` which CUDA it binds. NVIDIA publishes the
//! compiler on PyPI (the CUDA 12 wheel `nvidia-cuda-nvcc-cu12` holds only `ptxas`, no `nvcc`, hence CUDA 13);
//! the CUDA 13 wheels all unpack into one toolkit-shaped folder, `site-packages/nvidia/cu13` (`bin/nvcc` with
//! its `nvcc.profile`, `nvvm/bin/cicc`, `include/` with the runtime's, crt's and CCCL's headers), so no
//! assembled root is needed. They are installed into
//! `target/cuda-venv`, and `cargo check --all-targets` runs into its own target folder, `target/cuda-check`,
//! so that the normal builds' caches stay valid. `CUDA_COMPUTE_CAP` (default 80) replaces the `nvidia-smi`
//! query; `NVCC_CCBIN` names a host compiler if the machine's gcc is one this nvcc refuses. Only `check`:
//! linking would need the driver's `libcuda.so`, cuBLAS, cuRAND and NVRTC, which a GPU machine has.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use crate::util::{Result, cargo, ensure_venv, project_root, site_packages, spawn, target_dir, write_atomic};

/// The CUDA release checked against: the newest that candle's cudarc (0.19) knows (its build panics on
/// another). The wheels are the `nvcc` subset of NVIDIA's `cuda-toolkit==13.4.3` meta-package, plus CCCL
/// (`<nv/target>`, included by `cuda_fp16.h`) at the version that meta-package pins.
const CUDA: &str = "13.4";
const WHEELS: [&str; 5] = [
    "nvidia-cuda-nvcc==13.4.92",
    "nvidia-nvvm==13.4.92",
    "nvidia-cuda-crt==13.4.92",
    "nvidia-cuda-runtime==13.4.92",
    "nvidia-cuda-cccl==13.3.4.3.1",
];
/// The GPU architecture compiled for when `CUDA_COMPUTE_CAP` is not set (Ampere; CUDA 13 needs 75 or more).
const DEFAULT_COMPUTE_CAP: &str = "80";
/// The packages whose `cuda` feature is checked, with every target (tests, benches, the e2e tests).
const PACKAGES: [&str; 4] = ["hush-net", "hush-train", "hush-pipeline", "hush"];

pub fn run(args: &[String]) -> Result<()> {
    crate::args::Flags::parse(args, &[], 0, "cargo xtask cuda-check (CUDA_COMPUTE_CAP and NVCC_CCBIN are read)")?;
    let root = ensure_toolkit()?;
    let nvcc = root.join("bin").join("nvcc");
    let compute_cap = std::env::var("CUDA_COMPUTE_CAP").unwrap_or_else(|_| DEFAULT_COMPUTE_CAP.into());
    let path = std::env::var_os("PATH").unwrap_or_default();
    let path = std::env::join_paths(std::iter::once(root.join("bin")).chain(std::env::split_paths(&path)))
        .map_err(|e| format!("{}: cannot be put on PATH: {e}", root.display()))?;
    let mut cmd = Command::new(cargo());
    cmd.current_dir(project_root()).arg("check");
    for package in PACKAGES {
        cmd.args(["--package", package]);
    }
    cmd.args(["--features", "cuda", "--all-targets"])
        .env("CARGO_TARGET_DIR", target_dir().join("cuda-check"))
        .env("PATH", path)
        .env("NVCC", &nvcc)
        .env("CUDA_COMPUTE_CAP", &compute_cap);
    for var in ["CUDA_HOME", "CUDA_PATH", "CUDA_ROOT"] {
        cmd.env(var, &root);
    }
    let start = Instant::now();
    match spawn(&mut cmd) {
        Ok(()) => {
            println!(
                "cuda-check: ok: {} compile with --features cuda (all targets) against CUDA {CUDA} (nvcc from PyPI, \
                 sm_{compute_cap}) in {:.0} s",
                PACKAGES.join(", "),
                start.elapsed().as_secs_f64()
            );
            Ok(())
        }
        Err(e) => Err(format!(
            "cuda-check: FAILED: the `cuda` feature does not compile against CUDA {CUDA} (sm_{compute_cap}); \
             the compiler's errors are above ({e})"
        )),
    }
}

fn venv_dir() -> PathBuf {
    target_dir().join("cuda-venv")
}

/// Written after the wheels installed and their nvcc ran: names the wheels, so a change of pins reinstalls.
fn marker() -> PathBuf {
    venv_dir().join("hush-cuda-wheels.ok")
}

fn marker_text() -> String {
    WHEELS.join("\n") + "\n"
}

/// The toolkit folder the wheels unpack into.
fn toolkit_root(venv: &Path) -> Result<PathBuf> {
    Ok(site_packages(venv)?.join("nvidia").join("cu13"))
}

/// Installs the pinned wheels unless they are there already, checks that their nvcc runs and is the expected
/// release, and returns the toolkit folder.
pub(crate) fn ensure_toolkit() -> Result<PathBuf> {
    let venv = venv_dir();
    let installed = std::fs::read_to_string(marker()).is_ok_and(|t| t == marker_text());
    if installed
        && let Ok(root) = toolkit_root(&venv)
        && root.join("bin").join("nvcc").is_file()
    {
        return Ok(root);
    }
    let python = ensure_venv(&venv, "3.9+")?;
    spawn(Command::new(&python).args(["-m", "pip", "install", "--quiet"]).args(WHEELS))?;
    let root = toolkit_root(&venv)?;
    let nvcc = root.join("bin").join("nvcc");
    let version = Command::new(&nvcc)
        .arg("--version")
        .output()
        .map_err(|e| format!("{}: cannot run the wheels' nvcc: {e}", nvcc.display()))?;
    let version = String::from_utf8_lossy(&version.stdout);
    if !version.contains(&format!("release {CUDA},")) {
        return Err(format!(
            "{}: expected nvcc of CUDA {CUDA} (pinned in xtask/src/cuda_check.rs), it says:\n{version}",
            nvcc.display()
        ));
    }
    write_atomic(&marker(), &marker_text())?;
    Ok(root)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The toolkit's wheels are one release: bumping `CUDA` without them (or one wheel alone) would check
    /// against a mix, or fail only after a long install.
    #[test]
    fn the_toolkit_wheels_are_pinned_to_the_checked_release() {
        for wheel in WHEELS.iter().filter(|w| !w.starts_with("nvidia-cuda-cccl")) {
            let version = wheel.split_once("==").map(|(_, v)| v).unwrap_or_default();
            assert!(version.starts_with(&format!("{CUDA}.")), "{wheel} is not CUDA {CUDA}");
        }
        assert!(WHEELS.iter().all(|w| w.contains("==")), "every wheel is pinned: {WHEELS:?}");
    }
}
