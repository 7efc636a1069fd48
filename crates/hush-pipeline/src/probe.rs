//! The accept-or-retry probe shared by generated views and procedural scenes: a small, cheap render that
//! tells whether a camera sees enough light to be worth rendering.

use anyhow::Result;
use hush_dataset::luminance;
use hush_scene::{Film, Scene};
use hush_trace::{PixelSampler, RenderSettings, Renderer};

/// A candidate (view or scene) is kept when at least this fraction of its probe pixels receives light.
pub const MIN_LIT_FRACTION: f64 = 0.5;
/// Candidates tried before giving up (a generated view then keeps the best one).
pub const MAX_ATTEMPTS: u32 = 8;
/// The probe render: at most this many pixels along the longer side ...
pub const PROBE_SIZE: u32 = 32;
/// ... at this many samples per pixel.
pub const PROBE_SPP: u32 = 4;
/// The probe renders' seed ("PROBE"), mixed with the attempt.
pub const PROBE_SEED: u64 = 0x0050_524f_4245;

/// The probe's image size for a film: the film scaled down to [`PROBE_SIZE`] along its longer side (never up).
pub fn probe_size(film: &Film) -> (u32, u32) {
    let scale = PROBE_SIZE as f32 / film.width.max(film.height) as f32;
    if scale < 1.0 {
        (((film.width as f32 * scale).round() as u32).max(1), ((film.height as f32 * scale).round() as u32).max(1))
    } else {
        (film.width, film.height)
    }
}

/// The fraction of pixels that receive any light in a [`PROBE_SPP`]-spp render of `scene` at its
/// [`probe_size`], seeded with `seed`.
pub fn lit_fraction(renderer: &Renderer, scene: &Scene, seed: u64) -> Result<f64> {
    let mut probe = scene.clone();
    (probe.film.width, probe.film.height) = probe_size(&scene.film);
    // Independent positions, as before stratification existed: which cameras and generated scenes a probe
    // accepts stays what it was.
    let settings = RenderSettings { spp: PROBE_SPP, seed, pixel_sampler: PixelSampler::Independent };
    let out = renderer.render(&probe, &settings, &mut |_, _| {})?;
    let lit = out.color.data.chunks_exact(3).filter(|p| luminance(p) > 0.0).count();
    Ok(lit as f64 / (probe.film.width as f64 * probe.film.height as f64))
}
