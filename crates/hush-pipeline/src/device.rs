//! The one place that chooses Candle's device.

use anyhow::{Result, bail};
use candle_core::Device;

/// The device called `name`: `cpu`, or `cuda` (the first CUDA device) when built with the `cuda` feature.
/// `None` picks CUDA when built with it, else the CPU.
///
/// ```
/// assert!(hush_pipeline::device(Some("cpu")).unwrap().is_cpu());
/// assert!(hush_pipeline::device(Some("tpu")).unwrap_err().to_string().contains("use cpu or cuda"));
/// ```
pub fn device(name: Option<&str>) -> Result<Device> {
    match name.unwrap_or(if cfg!(feature = "cuda") { "cuda" } else { "cpu" }) {
        "cpu" => Ok(Device::Cpu),
        "cuda" => cuda(),
        other => bail!("unknown --device '{other}': use cpu or cuda"),
    }
}

#[cfg(feature = "cuda")]
fn cuda() -> Result<Device> {
    Ok(Device::new_cuda(0)?)
}

#[cfg(not(feature = "cuda"))]
fn cuda() -> Result<Device> {
    bail!("--device cuda: this hush was built without CUDA; rebuild with `cargo build -p hush --features cuda`")
}

/// Whether `name` is a device [`device`] knows (without opening it).
pub fn is_known(name: &str) -> bool {
    matches!(name, "cpu" | "cuda")
}
