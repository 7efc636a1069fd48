use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

pub type Result<T> = std::result::Result<T, String>;

/// The repository root (this crate lives in `<root>/xtask`).
///
/// `cargo run` (what `cargo xtask` is) sets `CARGO_MANIFEST_DIR` for the process it starts: that one is the
/// checkout being worked in. The value compiled in is only the fallback, because cargo does not rebuild
/// xtask for another checkout sharing the same target directory (its fingerprint ignores the path), and a
/// binary built in one clone would otherwise render, build and write into that clone.
pub fn project_root() -> PathBuf {
    let manifest_dir = std::env::var_os("CARGO_MANIFEST_DIR").map(PathBuf::from);
    let manifest_dir = manifest_dir.unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")));
    manifest_dir.parent().expect("xtask sits in the repository root").to_path_buf()
}

/// The cargo that runs us.
pub fn cargo() -> String {
    std::env::var("CARGO").unwrap_or_else(|_| "cargo".into())
}

/// The target directory cargo uses for this workspace.
pub fn target_dir() -> PathBuf {
    std::env::var_os("CARGO_TARGET_DIR").map(PathBuf::from).unwrap_or_else(|| project_root().join("target"))
}

/// Builds the `hush` binary (the dev profile optimizes dependencies, so the tests' build is
/// reused; `--release` builds with full optimization) and returns its path.
pub fn build_hush(release: bool) -> Result<PathBuf> {
    let mut cmd = Command::new(cargo());
    cmd.current_dir(project_root()).args(["build", "--package", "hush"]);
    if release {
        cmd.arg("--release");
    }
    spawn(&mut cmd)?;
    let exe = target_dir().join(if release { "release" } else { "debug" }).join("hush");
    if !exe.is_file() {
        return Err(format!("cargo built hush but {} is missing", exe.display()));
    }
    Ok(exe)
}

/// Runs a command, echoing it, and fails with its exit status.
pub fn spawn(cmd: &mut Command) -> Result<()> {
    let shown = format!(
        "{} {}",
        cmd.get_program().to_string_lossy(),
        cmd.get_args().map(|a| a.to_string_lossy()).collect::<Vec<_>>().join(" ")
    );
    eprintln!("$ {shown}");
    let start = Instant::now();
    let status = cmd.status().map_err(|e| format!("cannot start `{shown}`: {e}"))?;
    if !status.success() {
        return Err(format!("`{shown}` failed ({status})"));
    }
    eprintln!("  ({:.1} s)", start.elapsed().as_secs_f64());
    Ok(())
}

/// Runs a command, echoing it, and returns its standard output (standard error passes through).
pub fn output(cmd: &mut Command) -> Result<String> {
    let shown = format!(
        "{} {}",
        cmd.get_program().to_string_lossy(),
        cmd.get_args().map(|a| a.to_string_lossy()).collect::<Vec<_>>().join(" ")
    );
    eprintln!("$ {shown}");
    let out =
        cmd.stderr(std::process::Stdio::inherit()).output().map_err(|e| format!("cannot start `{shown}`: {e}"))?;
    if !out.status.success() {
        return Err(format!("`{shown}` failed ({})", out.status));
    }
    String::from_utf8(out.stdout).map_err(|e| format!("`{shown}` printed non-UTF-8: {e}"))
}

/// The 1-, 5- and 15-minute load averages (`uptime`), to judge how busy the machine was.
pub fn load_average() -> serde_json::Value {
    let text = std::fs::read_to_string("/proc/loadavg").unwrap_or_default();
    let v: Vec<f64> = text.split_whitespace().take(3).filter_map(|s| s.parse().ok()).collect();
    if v.len() == 3 { serde_json::json!(v) } else { serde_json::Value::Null }
}

/// Makes sure a Vulkan driver is installed: lavapipe (Mesa's CPU Vulkan) on Debian when
/// none is, with the one command that does it.
pub fn ensure_vulkan() -> Result<()> {
    let dirs = ["/usr/share/vulkan/icd.d", "/etc/vulkan/icd.d"];
    let has_icd = dirs.iter().any(|d| std::fs::read_dir(d).map(|mut r| r.next().is_some()).unwrap_or(false));
    let has_loader = [
        "/usr/lib/x86_64-linux-gnu/libvulkan.so.1",
        "/usr/lib/aarch64-linux-gnu/libvulkan.so.1",
        "/usr/lib/libvulkan.so.1",
    ]
    .iter()
    .any(|p| Path::new(p).exists());
    if has_icd && has_loader
        || std::env::var_os("VK_DRIVER_FILES").is_some()
        || std::env::var_os("VK_ICD_FILENAMES").is_some()
    {
        return Ok(());
    }
    const INSTALL: &str = "apt-get install -y libvulkan1 mesa-vulkan-drivers";
    if is_root() && Path::new("/usr/bin/apt-get").exists() {
        eprintln!("xtask: no Vulkan driver found; installing Mesa's CPU driver (lavapipe): {INSTALL}");
        spawn(Command::new("apt-get").args(["update", "-qq"]))?;
        return spawn(Command::new("apt-get").args(["install", "-y", "-qq", "libvulkan1", "mesa-vulkan-drivers"]));
    }
    Err(format!("no Vulkan driver found: install one, e.g. `sudo {INSTALL}` (Mesa's CPU driver, lavapipe)"))
}

/// Whether we run as root (and so may install system packages with apt-get).
pub fn is_root() -> bool {
    Command::new("id").arg("-u").output().map(|o| o.stdout.trim_ascii() == b"0").unwrap_or(false)
}

/// Reads a JSON file written by `hush`.
pub fn read_json(path: &Path) -> Result<serde_json::Value> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
    serde_json::from_str(&text).map_err(|e| format!("{}: {e}", path.display()))
}

/// Writes a JSON file atomically.
pub fn write_json(path: &Path, value: &serde_json::Value) -> Result<()> {
    write_atomic(path, &serde_json::to_string_pretty(value).expect("JSON values serialize"))
}

/// Writes a text file atomically (see [`write_atomic_with`]).
pub fn write_atomic(path: &Path, text: &str) -> Result<()> {
    write_atomic_with(path, |tmp| std::fs::write(tmp, text))
}

/// xtask's one atomic writer: `write` fills a temporary file beside `path` (`.<name>.<pid>.tmp`, so that
/// processes writing the same file do not share it), which is then renamed over `path`; the folder is created.
/// A killed process never leaves a partial file, and a failed write removes its temporary.
pub fn write_atomic_with(path: &Path, write: impl FnOnce(&Path) -> std::io::Result<()>) -> Result<()> {
    let dir = path.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."));
    std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let name = path.file_name().ok_or_else(|| format!("{}: not a file name", path.display()))?;
    let tmp = dir.join(format!(".{}.{}.tmp", name.to_string_lossy(), std::process::id()));
    let done = write(&tmp)
        .map_err(|e| format!("{}: {e}", tmp.display()))
        .and_then(|()| std::fs::rename(&tmp, path).map_err(|e| format!("{}: {e}", path.display())));
    if done.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    done
}

/// A Python venv's interpreter.
pub fn venv_python(venv: &Path) -> PathBuf {
    venv.join("bin").join("python")
}

/// Creates the Python venv `venv` when it has no interpreter yet (with `$PYTHON`, else `python3`; `min_python`
/// names the version the packages need, for the error message), brings its pip up to date and returns the
/// venv's interpreter.
pub fn ensure_venv(venv: &Path, min_python: &str) -> Result<PathBuf> {
    let python = venv_python(venv);
    if !python.is_file() {
        let system = std::env::var("PYTHON").unwrap_or_else(|_| "python3".into());
        spawn(Command::new(&system).args(["-m", "venv"]).arg(venv)).map_err(|e| {
            format!("{e}\n(a Python {min_python} with venv is needed: on Debian `apt-get install -y python3-venv`)")
        })?;
    }
    spawn(Command::new(&python).args(["-m", "pip", "install", "--quiet", "--upgrade", "pip"]))?;
    Ok(python)
}

/// The `site-packages` folder of a venv (`<venv>/lib/python3.X/site-packages`), where pip put the packages.
pub fn site_packages(venv: &Path) -> Result<PathBuf> {
    let lib = venv.join("lib");
    let entries = std::fs::read_dir(&lib).map_err(|e| format!("{}: {e}", lib.display()))?;
    entries
        .filter_map(|e| e.ok())
        .map(|e| e.path().join("site-packages"))
        .find(|p| p.is_dir())
        .ok_or_else(|| format!("no lib/python3.*/site-packages in the venv {}", venv.display()))
}

/// Every regular file below `dir` (recursively; symbolic links are not followed), sorted.
pub fn files_below(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        let Ok(entries) = std::fs::read_dir(&d) else { continue };
        for entry in entries.flatten() {
            match entry.file_type() {
                Ok(t) if t.is_dir() => stack.push(entry.path()),
                Ok(t) if t.is_file() => out.push(entry.path()),
                _ => {}
            }
        }
    }
    out.sort();
    out
}

/// `path` relative to `dir`, as text.
pub fn relative(path: &Path, dir: &Path) -> String {
    path.strip_prefix(dir).unwrap_or(path).display().to_string()
}

/// Whether `path` names a temporary file of an interrupted atomic write (`.<name>.<...>.tmp`, hush's and
/// xtask's alike).
pub fn is_temporary(path: &str) -> bool {
    path.rsplit('/').next().is_some_and(|n| n.starts_with('.') && n.ends_with(".tmp"))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scratch(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("xtask-util-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    #[test]
    fn site_packages_is_found_whatever_the_python_version_and_its_absence_names_the_venv() {
        let venv = scratch("venv");
        let err = site_packages(&venv).unwrap_err();
        assert!(err.contains(&venv.display().to_string()), "{err}");
        std::fs::create_dir_all(venv.join("lib/python3.13/site-packages")).unwrap();
        assert_eq!(site_packages(&venv).unwrap(), venv.join("lib/python3.13/site-packages"));
        std::fs::remove_dir_all(&venv).unwrap();
    }

    #[test]
    fn write_atomic_creates_the_folder_replaces_the_file_and_leaves_no_temporary() {
        let dir = scratch("atomic");
        let path = dir.join("sub/marker.ok");
        write_atomic(&path, "first").unwrap();
        write_atomic(&path, "second").unwrap();
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "second");
        let names: Vec<_> = std::fs::read_dir(dir.join("sub")).unwrap().map(|e| e.unwrap().file_name()).collect();
        assert_eq!(names, ["marker.ok"]);
        // A write that fails keeps the old file and removes its temporary.
        let err = write_atomic_with(&path, |tmp| {
            std::fs::write(tmp, "half")?;
            Err(std::io::Error::other("disk full"))
        })
        .unwrap_err();
        assert!(err.contains("disk full"), "{err}");
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "second");
        assert_eq!(std::fs::read_dir(dir.join("sub")).unwrap().count(), 1);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
