//! `cargo xtask test`: installs what a fresh machine lacks (a Vulkan driver), then runs every
//! test of the workspace, the browser test of `report.html` where Chromium is installed, then the thesis's
//! sweeps at their tiny scale (a real dataset, training and evaluation of every sweep's runs, and the
//! aggregate report), from scratch.

use std::process::Command;

use crate::util::{Result, ensure_vulkan, project_root, spawn, target_dir};

pub fn run(args: &[String]) -> Result<()> {
    ensure_vulkan()?;
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let mut test = Command::new(cargo);
    test.current_dir(project_root()).args(["test", "--workspace"]).args(args);
    // As `hush` does for itself: Mesa's device-selection layer would ask a window system for the default GPU
    // in every test that opens one, and libwayland print "XDG_RUNTIME_DIR is invalid" on a headless machine.
    if std::env::var_os("NODEVICE_SELECT").is_none() && std::env::var_os("MESA_VK_DEVICE_SELECT").is_none() {
        test.env("NODEVICE_SELECT", "1");
    }
    spawn(&mut test)?;
    if !args.is_empty() {
        // A filtered test run (`cargo xtask test <filter>`) is not the whole suite.
        return Ok(());
    }
    // The report's page in a real browser, where one is installed (`cargo xtask eval --check-html` installs it).
    if crate::eval::has_chromium() {
        spawn(&mut crate::eval::browser_test())?;
    } else {
        eprintln!(
            "xtask: Chromium is not installed: the browser test of report.html is left out (`apt-get install -y chromium`, or `cargo xtask eval --check-html`)"
        );
    }
    let out = target_dir().join("test-sweeps");
    if out.exists() {
        std::fs::remove_dir_all(&out).map_err(|e| format!("cannot clear {}: {e}", out.display()))?;
    }
    crate::sweep::run(&["all".into(), "--scale".into(), "tiny".into(), "--out".into(), out.display().to_string()])
}
