//! The hand-coded feature-guided filter (`hush_eval::guided`).

use hush_dataset::{Image, read_rgb};
use hush_eval::guided::{GuidedParams, guided_filter, noise_sigma_mad};
use hush_eval::{compare, rel_mse};

use crate::shared_reference;

/// A seeded xorshift stream of uniforms in (0, 1].
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Rng {
        Rng(seed.max(1))
    }

    pub fn uniform(&mut self) -> f32 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        ((self.0 >> 40) as f32 + 1.0) / (1u64 << 24) as f32
    }

    /// Monte-Carlo-like multiplicative noise: mean 1, heavy right tail (an exponential mixed with 1).
    pub fn mc_factor(&mut self) -> f32 {
        0.5 + 0.5 * -self.uniform().ln()
    }
}

/// A 64x48 scene: albedo 0.8 left of x = 32 and 0.2 right of it, smooth lighting, normals facing +z except a
/// tilted band at the bottom. Returns (clean color, albedo, normal).
fn scene() -> (Image, Image, Image) {
    let (w, h) = (64, 48);
    let albedo = Image::from_fn(w, h, 3, |x, _, c| if x < 32 { [0.8, 0.7, 0.6][c] } else { [0.2, 0.25, 0.3][c] });
    let normal = Image::from_fn(w, h, 3, |_, y, c| if y < 36 { [0.0, 0.0, 1.0][c] } else { [0.0, 0.6, 0.8][c] });
    let light = |x: usize, y: usize| 0.6 + 0.3 * (x as f32 / 64.0) + if y < 36 { 0.2 } else { -0.3 };
    let clean = Image::from_fn(w, h, 3, |x, y, c| albedo.pixel(x, y)[c] * light(x, y));
    (clean, albedo, normal)
}

fn noisy(clean: &Image, seed: u64) -> Image {
    let mut rng = Rng::new(seed);
    let mut out = clean.clone();
    for p in out.data.chunks_exact_mut(3) {
        let f = rng.mc_factor();
        p.iter_mut().for_each(|v| *v *= f);
    }
    out
}

#[test]
fn reduces_error_on_a_synthetic_noisy_image() {
    let (clean, albedo, normal) = scene();
    let noisy = noisy(&clean, 7);
    let out = guided_filter(&noisy, Some(&albedo), Some(&normal), &GuidedParams::default()).unwrap();
    let (before, after) = (rel_mse(&noisy, &clean).unwrap(), rel_mse(&out, &clean).unwrap());
    eprintln!("synthetic: relMSE noisy {before:.5} -> guided {after:.5}");
    // The noise has relative variance 0.25; a 15x15 window with σ_s 4 averages tens of pixels, so anything
    // short of a 4x reduction would mean the weights collapse to the centre pixel.
    assert!(after < before / 4.0, "relMSE {before} -> {after}");
    // Without features it still denoises, but less well across the material edge.
    let color_only = guided_filter(&noisy, None, None, &GuidedParams::default()).unwrap();
    assert!(rel_mse(&color_only, &clean).unwrap() < before);
}

#[test]
fn preserves_an_albedo_edge() {
    let (clean, albedo, normal) = scene();
    let noisy = noisy(&clean, 11);
    let params = GuidedParams::default();
    let guided = guided_filter(&noisy, Some(&albedo), Some(&normal), &params).unwrap();
    // Mean color of the two columns on each side of the edge (x = 31 | 32), rows 4..32 (away from the normal
    // band). Noise averages over 28 rows x 3 channels: σ of that mean ≈ 0.5/√84·value ≈ 5 % of the value.
    let column_mean = |im: &Image, x: usize| (4..32).map(|y| im.pixel(x, y)[0] as f64).sum::<f64>() / 28.0;
    for x in [31, 32] {
        let (got, want) = (column_mean(&guided, x), column_mean(&clean, x));
        assert!((got / want - 1.0).abs() < 0.15, "column {x}: guided {got} vs clean {want}");
    }
    // Without the albedo guide the edge bleeds: the bright side darkens and the dark side brightens by far more.
    let unguided = guided_filter(&noisy, None, None, &params).unwrap();
    let bleed = column_mean(&unguided, 32) / column_mean(&clean, 32) - 1.0;
    let guided_bleed = column_mean(&guided, 32) / column_mean(&clean, 32) - 1.0;
    assert!(bleed > guided_bleed + 0.2, "dark side: unguided +{bleed:.3}, guided +{guided_bleed:.3}");
}

#[test]
fn constant_images_come_back_bit_for_bit() {
    let constant = Image::from_fn(24, 20, 3, |_, _, c| [0.3, 0.5, 0.7][c]);
    let albedo = Image::from_fn(24, 20, 3, |_, _, c| [0.9, 0.6, 0.001][c]);
    let normal = Image::from_fn(24, 20, 3, |_, _, c| [0.0, 1.0, 0.0][c]);
    let params = GuidedParams::default();
    assert_eq!(guided_filter(&constant, None, None, &params).unwrap().data, constant.data);
    assert_eq!(guided_filter(&constant, Some(&albedo), Some(&normal), &params).unwrap().data, constant.data);
    assert_eq!(noise_sigma_mad(&vec![0.25; 64], 8, 8), 0.0);
}

#[test]
fn non_finite_and_mismatched_input_are_clear_errors() {
    let (clean, albedo, normal) = scene();
    let params = GuidedParams::default();
    for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
        let mut c = clean.clone();
        c.pixel_mut(5, 6)[1] = bad;
        let err = guided_filter(&c, Some(&albedo), Some(&normal), &params).unwrap_err().to_string();
        assert!(err.contains("color") && err.contains("(x 5, y 6), channel 1"), "{err}");
        let mut n = normal.clone();
        n.pixel_mut(1, 2)[0] = bad;
        let err = guided_filter(&clean, Some(&albedo), Some(&n), &params).unwrap_err().to_string();
        assert!(err.contains("normal") && err.contains("(x 1, y 2)"), "{err}");
    }
    let err = guided_filter(&clean, Some(&Image::zeros(10, 10, 3)), None, &params).unwrap_err().to_string();
    assert!(err.contains("albedo") && err.contains("10x10x3") && err.contains("64x48x3"), "{err}");
    let err = guided_filter(&clean, None, Some(&Image::zeros(64, 48, 1)), &params).unwrap_err().to_string();
    assert!(err.contains("normal") && err.contains("3 channels"), "{err}");
    let zero = GuidedParams { sigma_spatial: 0.0, ..params };
    assert!(guided_filter(&clean, None, None, &zero).unwrap_err().to_string().contains("sigma"));
}

/// A `size`² crop of the Mitsuba Cornell box at 16 spp with its albedo and normal, and the 1792-spp reference.
pub fn cbox_crop(x: usize, y: usize, size: usize) -> (Image, Image, Image, Image) {
    let oidn = shared_reference("oidn-2.5.1");
    let read = |p: std::path::PathBuf| read_rgb(p).unwrap().crop(x, y, size, size).unwrap();
    (
        read(oidn.join("input_color.exr")),
        read(oidn.join("input_albedo.exr")),
        read(oidn.join("input_normal.exr")),
        read(shared_reference("mitsuba-cbox").join("mitsuba_1792spp.exr")),
    )
}

#[test]
fn denoises_the_mitsuba_cornell_box() {
    // A 96² crop across the tall box's edge and the red wall: edges in albedo and normal, soft shadows.
    let (color, albedo, normal, reference) = cbox_crop(100, 250, 96);
    let out = guided_filter(&color, Some(&albedo), Some(&normal), &GuidedParams::default()).unwrap();
    let (before, after) = (compare(&color, &reference).unwrap(), compare(&out, &reference).unwrap());
    eprintln!("cbox 16 spp crop: noisy {before:?}\n                  guided {after:?}");
    // 16 spp has relMSE ≈ 0.017; a working filter roughly halves the RMSE (≥ 5 dB) and raises SSIM.
    assert!(after.psnr > before.psnr + 5.0, "PSNR {} -> {}", before.psnr, after.psnr);
    assert!(after.ssim > before.ssim && after.rel_mse < before.rel_mse / 2.0);
}
