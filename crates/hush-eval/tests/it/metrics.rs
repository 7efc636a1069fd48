use hush_dataset::{Image, read_rgb};
use hush_eval::{color_shift, compare, mae, mse, psnr, psnr_of_mse, rel_mse, ssim, ssim_tonemapped};

use crate::{fixture, shared_reference};

#[test]
fn identical_images_have_infinite_psnr_and_unit_ssim() {
    let im = Image::from_fn(16, 12, 3, |x, y, c| 0.05 * (x + 2 * y + c) as f32);
    let m = compare(&im, &im).unwrap();
    assert_eq!(m.psnr, f64::INFINITY);
    assert_eq!((m.mse, m.mae, m.rel_mse), (0.0, 0.0, 0.0));
    assert!((m.ssim - 1.0).abs() < 1e-6, "{}", m.ssim);
    assert_eq!(psnr(&im, &im).unwrap(), f64::INFINITY);
}

#[test]
fn known_values_by_hand() {
    // Reference: black 16x16, so no bin is above 1e-8 and the exposure is 1. Test: one pixel at 1e6, which
    // tonemaps to 1 in every channel; all others 0. Tonemapped MSE = MAE = 3 / (16·16·3) = 1/256,
    // PSNR = 10·log10(256) = 24.0824 dB, relMSE = (1e6)² / 0.01 · 3 / 768 = 3.90625e11.
    let reference = Image::zeros(16, 16, 3);
    let mut test = reference.clone();
    test.pixel_mut(5, 7).copy_from_slice(&[1e6; 3]);
    let m = compare(&test, &reference).unwrap();
    assert_eq!(m.exposure, 1.0);
    assert!((m.mse - 1.0 / 256.0).abs() < 1e-12, "{}", m.mse);
    assert!((m.mae - 1.0 / 256.0).abs() < 1e-12, "{}", m.mae);
    assert!((m.psnr - 24.082_399_653_118_497).abs() < 1e-9, "{}", m.psnr);
    assert!((m.rel_mse / 3.90625e11 - 1.0).abs() < 1e-9, "{}", m.rel_mse);
    // The single-metric functions agree with `compare`.
    assert_eq!(psnr(&test, &reference).unwrap(), m.psnr);
    assert_eq!(mse(&test, &reference).unwrap(), m.mse);
    assert_eq!(mae(&test, &reference).unwrap(), m.mae);
    assert_eq!(rel_mse(&test, &reference).unwrap(), m.rel_mse);
    assert_eq!(ssim(&test, &reference).unwrap(), m.ssim);
}

fn read_f32(name: &str) -> Vec<f32> {
    let bytes = std::fs::read(fixture(name)).unwrap();
    bytes.chunks_exact(4).map(|b| f32::from_le_bytes(b.try_into().unwrap())).collect()
}

#[test]
fn ssim_matches_scikit_image() {
    // Produced by tests/it/fixtures/ssim_skimage.py (scikit-image 0.26.0, configured like OIDN's SSIM).
    let expected: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(fixture("ssim_expected.json")).unwrap()).unwrap();
    let (h, w, c) = (32, 40, 3);
    assert_eq!((expected["height"].as_u64(), expected["width"].as_u64()), (Some(h as u64), Some(w as u64)));
    let a = Image::new(w, h, c, read_f32("ssim_a.f32")).unwrap();
    let b = Image::new(w, h, c, read_f32("ssim_b.f32")).unwrap();

    let value = ssim_tonemapped(&b, &a).unwrap();
    let want = expected["ssim"].as_f64().unwrap();
    // hush-net computes in f32 (scikit-image in f64).
    assert!((value - want).abs() < 2e-5, "hush {value} vs scikit-image {want}");
    assert!((ssim_tonemapped(&a, &b).unwrap() - value).abs() < 1e-6, "SSIM is symmetric");

    let mse: f64 = a.data.iter().zip(&b.data).map(|(x, y)| (f64::from(*x) - f64::from(*y)).powi(2)).sum::<f64>()
        / a.data.len() as f64;
    let want = expected["psnr"].as_f64().unwrap();
    assert!((psnr_of_mse(mse) - want).abs() < 1e-9, "{} vs {want}", psnr_of_mse(mse));
}

#[test]
fn errors_name_sizes_and_bad_pixels() {
    let a = Image::zeros(16, 16, 3);
    let err = compare(&a, &Image::zeros(16, 12, 3)).unwrap_err().to_string();
    assert!(err.contains("16x16x3") && err.contains("16x12x3"), "{err}");

    let mut nan = a.clone();
    nan.pixel_mut(2, 9)[1] = f32::NAN;
    let err = compare(&nan, &a).unwrap_err().to_string();
    assert!(err.contains("test image") && err.contains("(x 2, y 9), channel 1"), "{err}");
    let err = compare(&a, &nan).unwrap_err().to_string();
    assert!(err.contains("reference image"), "{err}");

    let err = ssim(&Image::zeros(8, 8, 3), &Image::zeros(8, 8, 3)).unwrap_err().to_string();
    assert!(err.contains("8x8"), "{err}");
}

#[test]
fn mitsuba_renders_improve_with_spp() {
    let dir = shared_reference("mitsuba-cbox");
    let reference = read_rgb(dir.join("mitsuba_1792spp.exr")).unwrap();
    let m16 = compare(&read_rgb(dir.join("mitsuba_16spp.exr")).unwrap(), &reference).unwrap();
    let m64 = compare(&read_rgb(dir.join("mitsuba_64spp.exr")).unwrap(), &reference).unwrap();
    eprintln!("mitsuba cbox vs 1792 spp: 16 spp {m16:?}\n                          64 spp {m64:?}");
    assert!(m64.psnr > m16.psnr + 4.0, "{} vs {}", m64.psnr, m16.psnr);
    assert!(m64.ssim > m16.ssim && m16.ssim > 0.3 && m64.ssim < 1.0);
    // shared/reference/mitsuba-cbox/README.md: relMSE ≈ 0.265 / spp (plus the 1792-spp reference's own noise).
    assert!((0.012..0.022).contains(&m16.rel_mse), "{}", m16.rel_mse);
    let ratio = m16.rel_mse / m64.rel_mse;
    assert!((3.3..4.5).contains(&ratio), "relMSE 16/64 spp = {ratio}");
}

/// MS-SSIM is reported only where its 5 scales fit (a side of at least 176 px), and then agrees with
/// hush-net's loss code on the tonemapped images.
#[test]
fn ms_ssim_needs_five_scales() {
    assert_eq!(hush_eval::MS_SSIM_MIN_SIDE, 176);
    let small = Image::from_fn(175, 200, 3, |x, y, _| 0.1 + 0.001 * (x + y) as f32);
    assert_eq!(compare(&small, &small).unwrap().ms_ssim, None);
    let reference = Image::from_fn(176, 180, 3, |x, y, c| 0.1 + 0.002 * ((x * 7 + y * 3 + c) % 50) as f32);
    let mut test = reference.clone();
    for (i, v) in test.data.iter_mut().enumerate() {
        *v *= 1.0 + 0.3 * ((i * 2_654_435_761) % 1000) as f32 / 1000.0;
    }
    assert!((compare(&reference, &reference).unwrap().ms_ssim.unwrap() - 1.0).abs() < 1e-5);
    let m = compare(&test, &reference).unwrap();
    let exposure = hush_eval::exposure_of(&reference).unwrap();
    let direct =
        hush_eval::ms_ssim_tonemapped(&hush_eval::tonemap(&test, exposure), &hush_eval::tonemap(&reference, exposure));
    let ms = m.ms_ssim.unwrap();
    assert_eq!(Some(ms), direct.unwrap());
    assert!(ms < 1.0 && ms > m.ssim, "noise hurts the finest scale most: MS-SSIM {ms} vs SSIM {}", m.ssim);
}

/// The colour shift is the largest relative change of a channel's image mean (of the images given): red 2 % brighter and blue 1 %
/// darker is 0.02, whatever the noise around the mean; an unchanged image is 0, a black reference channel
/// has none.
#[test]
fn color_shift_is_the_largest_channel_mean_change() {
    let reference = Image::from_fn(16, 16, 3, |x, y, c| 0.2 + 0.1 * c as f32 + 0.01 * (x + y) as f32);
    let shifted = Image::from_fn(16, 16, 3, |x, y, c| {
        let wobble = if (x + y) % 2 == 0 { 0.05 } else { -0.05 };
        reference.pixel(x, y)[c] * [1.02, 1.0, 0.99][c] + if c == 1 { wobble } else { 0.0 }
    });
    let shift = color_shift(&shifted, &reference).unwrap().unwrap();
    assert!((shift - 0.02).abs() < 1e-6, "{shift}");
    assert_eq!(color_shift(&reference, &reference).unwrap(), Some(0.0));
    // The evaluation measures it as the eye sees the images: tonemapped with the reference's exposure.
    let e = hush_eval::exposure_of(&reference).unwrap();
    let seen = color_shift(&hush_eval::tonemap(&shifted, e), &hush_eval::tonemap(&reference, e)).unwrap();
    assert_eq!(compare(&shifted, &reference).unwrap().color_shift, seen);
    assert!(seen.unwrap() > 0.0 && seen.unwrap() < shift, "a tonemap compresses a 2 % brightening: {seen:?}");
    let black = Image::from_fn(16, 16, 3, |_, _, c| if c == 0 { 0.0 } else { 1.0 });
    assert_eq!(color_shift(&reference, &black).unwrap(), None);
}
