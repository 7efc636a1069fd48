//! The hush path tracer: WGSL compute kernels run through wgpu.
//!
//! [`GpuContext::new`] opens a Vulkan, Metal or DX12 adapter (never OpenGL; on a machine
//! without a GPU, Mesa's lavapipe) and says which one it got. [`Renderer::render`] traces a
//! [`hush_scene::Scene`] and returns the beauty image with its per-pixel variance and the
//! auxiliary feature images (albedo, diffuse, specular, normal) as [`hush_dataset::Image`]s.
//!
//! ```no_run
//! use hush_trace::{GpuContext, Renderer, RenderSettings};
//! let scene = hush_scene::Scene::load("scene.xml".as_ref())?;
//! let gpu = GpuContext::new()?;
//! eprintln!("rendering on {}", gpu.describe());
//! let out = Renderer::new(&gpu)?.render(&scene, &RenderSettings::new(16, 7), &mut |_, _| {})?;
//! assert_eq!(out.color.channels, 3);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod gpu;
#[cfg(test)]
mod probe;
mod render;
mod rough;
mod scan;
mod upload;
mod wide;

pub use gpu::{GpuContext, INSTALL_HINT};
pub use render::{
    KERNEL_SOURCE, MAX_CACHED_KERNELS, PixelSampler, RenderOutput, RenderSettings, Renderer, kernel_source,
};
pub use scan::SceneLiterals;
pub use upload::{FLAT_SCAN_MAX_TRIANGLES, KernelFeatures, flat_scan_cost};

/// Why a render could not run.
#[derive(Debug, thiserror::Error)]
pub enum TraceError {
    #[error("{0}")]
    NoAdapter(String),
    #[error("GPU error: {0}")]
    Gpu(String),
    #[error("invalid render request: {0}")]
    Invalid(String),
}
