//! `cargo xtask test`: installs what a fresh machine lacks (a Vulkan driver), then runs every
//! test of the workspace.

use std::process::Command;

use crate::util::{Result, ensure_vulkan, project_root, spawn};

pub fn run(args: &[String]) -> Result<()> {
    ensure_vulkan()?;
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    spawn(Command::new(cargo).current_dir(project_root()).args(["test", "--workspace"]).args(args))
}
