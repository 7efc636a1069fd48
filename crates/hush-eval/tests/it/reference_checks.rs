//! hush-eval's metrics against values computed independently in Python by `tests/fixtures/make_fixtures.py`
//! (numpy, scikit-image 0.25.2, flip-evaluator 1.7), under the convention written in that script and in
//! `hush_eval::CONVENTIONS`.

use std::path::{Path, PathBuf};

use hush_dataset::{Image, read_rgb};
use hush_eval::external::read_npy;
use hush_eval::{compare, exposure_of, psnr_of_mse, ssim_tonemapped, tonemap};

use crate::shared_reference;

/// `tests/fixtures/<name>` (reference values and the script that made them).
pub fn reference_fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures").join(name)
}

pub fn expected(name: &str) -> serde_json::Value {
    let path = reference_fixture(name);
    serde_json::from_str(&std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))).unwrap()
}

/// Test and reference of fixture pair `name` (linear HDR, 48x40).
pub fn pair(name: &str) -> (Image, Image) {
    let read = |kind: &str| read_npy(&reference_fixture(&format!("pair_{name}_{kind}.npy"))).unwrap();
    (read("test"), read("reference"))
}

fn close(what: &str, got: f64, want: f64, tol: f64) {
    assert!((got - want).abs() <= tol, "{what}: hush {got} vs Python {want} (tolerance {tol})");
}

#[test]
fn psnr_ssim_match_scikit_image_on_tonemapped_pairs() {
    let expected = expected("metrics_expected.json");
    for name in ["a", "b"] {
        let want = &expected["pairs"][name];
        let (test, reference) = pair(name);
        let exposure = exposure_of(&reference).unwrap();
        // Autoexposure is computed in f64 and rounded to f32 on both sides.
        close("exposure", f64::from(exposure), want["exposure"].as_f64().unwrap(), 1e-6);
        let (t, r) = (tonemap(&test, exposure), tonemap(&reference, exposure));
        // On the same tonemapped inputs: PSNR through hush's MSE (f64 sums: agrees to rounding), SSIM through
        // hush-net (f32 convolutions vs scikit-image's f64: 2e-5, as in metrics.rs).
        let mse = t.data.iter().zip(&r.data).map(|(a, b)| (f64::from(*a) - f64::from(*b)).powi(2)).sum::<f64>()
            / t.data.len() as f64;
        close("PSNR of tonemapped", psnr_of_mse(mse), want["psnr_tonemapped"].as_f64().unwrap(), 1e-4);
        close("SSIM of tonemapped", ssim_tonemapped(&t, &r).unwrap(), want["ssim_tonemapped"].as_f64().unwrap(), 2e-5);
        // The whole convention from linear images (tonemap in f32 here, f64 in numpy: 1e-4 dB, 2e-5 SSIM).
        let m = compare(&test, &reference).unwrap();
        close("PSNR", m.psnr, want["psnr"].as_f64().unwrap(), 1e-3);
        close("SSIM", m.ssim, want["ssim"].as_f64().unwrap(), 2e-5);
        close("MAE", m.mae, want["mae"].as_f64().unwrap(), 1e-6);
        close("MSE", m.mse, want["mse"].as_f64().unwrap(), 1e-7);
        close("relMSE", m.rel_mse / want["rel_mse"].as_f64().unwrap(), 1.0, 1e-5);
    }
}

#[test]
fn oidn_reference_outputs_score_as_computed_by_numpy() {
    // OIDN 2.5.1's own outputs on Mitsuba's 16-spp Cornell box, scored against Mitsuba's independent 1792-spp
    // render. Tolerances: hush tonemaps in f32 (numpy in f64), SSIM runs in f32 through hush-net; over 512²
    // pixels the f32 rounding averages out to < 1e-5 in SSIM and < 1e-3 dB in PSNR.
    let expected = expected("oidn_expected.json");
    let reference = read_rgb(shared_reference("mitsuba-cbox").join("mitsuba_1792spp.exr")).unwrap();
    let mut psnr = std::collections::BTreeMap::new();
    for name in ["input_color", "oidn_rt_hdr_alb_nrm", "oidn_rt_hdr_alb_nrm_small", "oidn_rt_hdr"] {
        let want = &expected["images"][name];
        let image = read_rgb(shared_reference("oidn-2.5.1").join(format!("{name}.exr"))).unwrap();
        let m = compare(&image, &reference).unwrap();
        eprintln!("{name}: {m:?}");
        close(&format!("{name} exposure"), f64::from(m.exposure), want["exposure"].as_f64().unwrap(), 1e-6);
        close(&format!("{name} PSNR"), m.psnr, want["psnr"].as_f64().unwrap(), 1e-3);
        close(&format!("{name} SSIM"), m.ssim, want["ssim"].as_f64().unwrap(), 2e-5);
        close(&format!("{name} MAE"), m.mae, want["mae"].as_f64().unwrap(), 1e-6);
        close(&format!("{name} MSE"), m.mse / want["mse"].as_f64().unwrap(), 1.0, 1e-4);
        close(&format!("{name} relMSE"), m.rel_mse / want["rel_mse"].as_f64().unwrap(), 1.0, 1e-4);
        psnr.insert(name, m.psnr);
    }
    // And the order the thesis reports: OIDN with features beats the noisy input by far.
    assert!(psnr["oidn_rt_hdr_alb_nrm"] > psnr["input_color"] + 10.0, "{psnr:?}");
}
