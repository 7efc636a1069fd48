//! LDR-FLIP against NVIDIA's reference implementation (PyPI `flip-evaluator` 1.7), values computed by
//! `tests/fixtures/make_fixtures.py`.

use hush_dataset::{Image, read_rgb};
use hush_eval::external::read_npy;
use hush_eval::flip::{DEFAULT_PPD, flip, flip_with_ppd};
use hush_eval::{exposure_of, tonemap};

use crate::reference_checks::{expected, pair, reference_fixture};
use crate::shared_reference;

#[test]
fn default_ppd_is_the_reference_implementations() {
    let ppd = expected("metrics_expected.json")["pairs"]["a"]["flip_ppd"].as_f64().unwrap();
    assert!((f64::from(DEFAULT_PPD) - ppd).abs() < 1e-4, "{DEFAULT_PPD} vs {ppd}");
}

#[test]
fn flip_matches_flip_evaluator() {
    // Both compute in f32 with the same filters and order of operations; differences come from libm `powf`/`exp`
    // and compiler contraction: per pixel < 1e-4 (the map is in [0, 1]), the mean < 1e-5.
    let expected = expected("metrics_expected.json");
    for name in ["a", "b"] {
        let (test, reference) = pair(name);
        let exposure = exposure_of(&reference).unwrap();
        let result = flip(&tonemap(&test, exposure), &tonemap(&reference, exposure)).unwrap();
        let want_map = read_npy(&reference_fixture(&format!("pair_{name}_flip.npy"))).unwrap();
        assert_eq!((result.map.width, result.map.height, result.map.channels), (48, 40, 1));
        assert_eq!((want_map.width, want_map.height), (48, 40));
        let max_diff = result.map.data.iter().zip(&want_map.data).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
        let want = expected["pairs"][name]["flip_mean"].as_f64().unwrap();
        eprintln!(
            "pair {name}: FLIP mean hush {} vs flip-evaluator {want}, max per-pixel diff {max_diff}",
            result.mean
        );
        assert!(max_diff < 1e-4, "pair {name}: per-pixel FLIP differs by {max_diff}");
        assert!((result.mean - want).abs() < 1e-5, "pair {name}: mean {} vs {want}", result.mean);
    }
}

#[test]
fn flip_of_oidn_output_matches_flip_evaluator_at_512() {
    // The same check at 512x512 on OIDN 2.5.1's output (see reference_checks.rs); mean tolerance as above.
    let expected = expected("oidn_expected.json");
    let reference = read_rgb(shared_reference("mitsuba-cbox").join("mitsuba_1792spp.exr")).unwrap();
    let image = read_rgb(shared_reference("oidn-2.5.1").join("oidn_rt_hdr_alb_nrm.exr")).unwrap();
    let exposure = exposure_of(&reference).unwrap();
    let got = flip(&tonemap(&image, exposure), &tonemap(&reference, exposure)).unwrap().mean;
    let want = expected["images"]["oidn_rt_hdr_alb_nrm"]["flip_mean"].as_f64().unwrap();
    assert!((got - want).abs() < 1e-5, "FLIP mean {got} vs flip-evaluator {want}");
}

#[test]
fn flip_is_zero_for_identical_images_and_rejects_bad_input() {
    let im = Image::from_fn(20, 16, 3, |x, y, c| ((x * 7 + y * 3 + c) % 11) as f32 / 10.0);
    let f = flip(&im, &im).unwrap();
    assert!(f.map.data.iter().all(|&v| v == 0.0) && f.mean == 0.0);

    let err = flip(&im, &Image::zeros(20, 15, 3)).unwrap_err().to_string();
    assert!(err.contains("20x16x3") && err.contains("20x15x3"), "{err}");
    let mut nan = im.clone();
    nan.pixel_mut(4, 5)[2] = f32::NAN;
    let err = flip(&nan, &im).unwrap_err().to_string();
    assert!(err.contains("FLIP test image") && err.contains("(x 4, y 5), channel 2"), "{err}");
    assert!(flip_with_ppd(&im, &im, 0.0).unwrap_err().to_string().contains("pixels per degree"));
    assert!(flip(&Image::zeros(4, 4, 1), &Image::zeros(4, 4, 1)).is_err());
}
