//! The golden test against the official Open Image Denoise 2.5.1 runtime: hush loads OIDN's own weights
//! (TZA), runs its inference path (`hush_net::denoise`) on the Mitsuba Cornell box of
//! `shared/reference/oidn-2.5.1/` and must reproduce OIDN's output.
//!
//! Tolerance: PSNR ≥ 80 dB after hush-eval's tonemap (OIDN's filmic curve and sRGB at the reference's
//! autoexposure), stricter than the 45 dB the issue asks for. Reached: 131.9 dB (`rt_hdr_alb_nrm`), 133.0 dB
//! (`rt_hdr_alb_nrm_small`), 133.8 dB (`rt_hdr`), i.e. RMS differences of ~2e-7 in [0, 1]: both sides
//! compute the same f32 network from the same f16 weights, and what remains is the order of floating-point
//! summation in the convolutions (OIDN's blocked CPU kernels vs candle's GEMM) and OIDN's f32 transfer
//! functions vs hush's f64 ones. Another CPU's SIMD width may change that rounding, not its magnitude, hence
//! the 50 dB margin. 45 dB would be too weak a bar: the network is robust enough that feeding it normal and
//! albedo in swapped order still reaches 42.6 dB (see `golden_test_can_fail`).

use candle_core::Device;
use hush_dataset::{Image, read_rgb};
use hush_eval::psnr;
use hush_net::{ModelInfo, UNet, denoise, load_tza};

use crate::shared_reference;

const GOLDEN_DB: f64 = 80.0;

fn weights(name: &str) -> Vec<u8> {
    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("../../data/weights/oidn-2.5.1/{name}.tza"));
    std::fs::read(&path).unwrap_or_else(|e| panic!("reading {}: {e}", path.display()))
}

fn input(name: &str) -> Image {
    read_rgb(shared_reference("oidn-2.5.1").join(format!("input_{name}.exr"))).unwrap()
}

fn run(net: &UNet, info: &ModelInfo) -> Image {
    let color = input("color");
    let aux: Vec<Image> = info.features.aux.iter().map(|f| input(f.long_name())).collect();
    let aux: Vec<&[f32]> = aux.iter().map(|a| a.data.as_slice()).collect();
    let out = denoise(net, info, color.width, color.height, &color.data, &aux).unwrap();
    Image::new(color.width, color.height, 3, out).unwrap()
}

fn check(model: &str) -> f64 {
    let (net, info) = load_tza(&weights(model), None, &Device::Cpu).unwrap();
    let ours = run(&net, &info);
    let theirs = read_rgb(shared_reference("oidn-2.5.1").join(format!("oidn_{model}.exr"))).unwrap();
    let db = psnr(&ours, &theirs).unwrap();
    eprintln!("{model}: PSNR {db:.2} dB against OIDN 2.5.1");
    assert!(db >= GOLDEN_DB, "{model}: PSNR {db:.2} dB against OIDN 2.5.1, below {GOLDEN_DB} dB");
    db
}

#[test]
fn golden_rt_hdr_alb_nrm() {
    check("rt_hdr_alb_nrm");
}

#[test]
fn golden_rt_hdr_alb_nrm_small() {
    check("rt_hdr_alb_nrm_small");
}

#[test]
fn golden_rt_hdr() {
    check("rt_hdr");
}

/// The bar can fail, and 45 dB would not: the same weights fed normal and albedo in swapped order (a
/// plausible wiring mistake) reach 42.6 dB; the color-only weights, a different denoiser, still 46.0 dB.
#[test]
fn golden_test_can_fail() {
    let (net, info) = load_tza(&weights("rt_hdr_alb_nrm"), None, &Device::Cpu).unwrap();
    let theirs = read_rgb(shared_reference("oidn-2.5.1").join("oidn_rt_hdr_alb_nrm.exr")).unwrap();
    let color = input("color");
    let (albedo, normal) = (input("albedo"), input("normal"));
    // Normal where the network expects albedo and vice versa (the feature list still says alb, nrm).
    let out = denoise(&net, &info, color.width, color.height, &color.data, &[&normal.data, &albedo.data]).unwrap();
    let db = psnr(&Image::new(color.width, color.height, 3, out).unwrap(), &theirs).unwrap();
    eprintln!("swapped auxiliary inputs: PSNR {db:.2} dB");
    assert!(db < GOLDEN_DB - 20.0, "swapped inputs reached {db:.2} dB");
    // The color-only weights on the same scene are a different denoiser, also well below the bar.
    let (color_net, color_info) = load_tza(&weights("rt_hdr"), None, &Device::Cpu).unwrap();
    let out = denoise(&color_net, &color_info, color.width, color.height, &color.data, &[]).unwrap();
    let db = psnr(&Image::new(color.width, color.height, 3, out).unwrap(), &theirs).unwrap();
    eprintln!("rt_hdr against rt_hdr_alb_nrm's output: PSNR {db:.2} dB");
    assert!(db < GOLDEN_DB - 20.0, "a different model reached {db:.2} dB");
}
