use hush_dataset::{Image, NegativePolicy, check_finite, check_radiance};

use crate::ramp;

#[test]
fn nan_detection_names_file_count_and_first_pixel() {
    let mut im = ramp(6, 4, 3, 0.0);
    assert!(check_finite("x.exr", &im).is_ok());
    im.pixel_mut(3, 1)[2] = f32::NAN;
    im.pixel_mut(5, 3)[0] = f32::INFINITY;
    let err = check_finite("renders/cbox_v0_000004.hdr.exr", &im).unwrap_err().to_string();
    for part in ["renders/cbox_v0_000004.hdr.exr", "2 non-finite", "(x 3, y 1), channel 2", "NaN"] {
        assert!(err.contains(part), "{part:?} missing in: {err}");
    }
}

#[test]
fn negative_radiance_is_an_error_by_default_or_clamped_on_request() {
    let mut im = Image::from_fn(3, 2, 3, |x, y, c| if (x, y, c) == (1, 1, 0) { -0.25 } else { 0.5 });
    let err = check_radiance("ref.exr", &mut im, NegativePolicy::default()).unwrap_err().to_string();
    assert!(err.contains("ref.exr") && err.contains("(x 1, y 1), channel 0") && err.contains("Clamp"), "{err}");
    assert_eq!(im.pixel(1, 1)[0], -0.25, "the error policy does not modify the image");

    assert_eq!(check_radiance("ref.exr", &mut im, NegativePolicy::Clamp).unwrap(), 1);
    assert_eq!(im.pixel(1, 1)[0], 0.0);
    assert_eq!(check_radiance("ref.exr", &mut im, NegativePolicy::Error).unwrap(), 0);

    im.data[0] = f32::NAN;
    assert!(check_radiance("ref.exr", &mut im, NegativePolicy::Clamp).is_err(), "NaN is never clamped away");
}
