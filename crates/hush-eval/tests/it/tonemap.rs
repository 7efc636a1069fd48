use hush_dataset::{Image, srgb_encode};
use hush_eval::{exposure_of, filmic, tonemap};

#[test]
fn filmic_known_values() {
    assert_eq!(filmic(0.0), 0.0);
    // OIDN's scale 1.758141 is the "exposure bias to match 18% middle gray": 0.18 maps to 0.18.
    assert!((filmic(0.18) - 0.18).abs() < 1e-6, "{}", filmic(0.18));
    // hable(1.758141 · 1) / hable(11.2) = 0.629982 (by hand from training/color.py's formula).
    assert!((filmic(1.0) - 0.629_982).abs() < 1e-5, "{}", filmic(1.0));
    // The white point 11.2 is reached at x = 11.2 / 1.758141; beyond it, the curve is clamped to 1.
    assert!((filmic(11.2 / 1.758141) - 1.0).abs() < 1e-6);
    assert_eq!(filmic(100.0), 1.0);
    assert_eq!(filmic(f32::MAX), 1.0);
    // Like OIDN's loader: NaN and negatives become 0, +Inf saturates.
    assert_eq!(filmic(f32::NAN), 0.0);
    assert_eq!(filmic(-3.0), 0.0);
    assert_eq!(filmic(f32::INFINITY), 1.0);
}

#[test]
fn tonemap_is_monotone_and_in_unit_range() {
    let xs: Vec<f32> = (0..2000).map(|i| 1e-4 * 1.01f32.powi(i)).collect(); // 1e-4 .. ~4e4
    let image = Image::new(xs.len(), 1, 1, xs.clone()).unwrap();
    for exposure in [0.25, 1.0, 4.0] {
        let t = tonemap(&image, exposure);
        assert!(t.data.iter().all(|v| (0.0..=1.0).contains(v)));
        assert!(t.data.windows(2).all(|w| w[0] <= w[1]), "not monotone at exposure {exposure}");
    }
    // 0.18 × exposure 1 → filmic 0.18 → sRGB.
    let grey = tonemap(&Image::from_fn(1, 1, 3, |_, _, _| 0.18), 1.0);
    assert!((grey.data[0] - srgb_encode(0.18)).abs() < 1e-6);
}

#[test]
fn exposure_comes_from_the_reference() {
    // A uniform 18% grey has luminance 0.18 (the coefficients sum to 1): exposure 1.
    let grey = Image::from_fn(40, 24, 3, |_, _, _| 0.18);
    assert!((exposure_of(&grey).unwrap() - 1.0).abs() < 1e-5);
    let bright = Image::from_fn(40, 24, 3, |_, _, _| 1.8);
    assert!((exposure_of(&bright).unwrap() - 0.1).abs() < 1e-6);
    assert!(exposure_of(&Image::zeros(4, 4, 1)).is_err());
}
