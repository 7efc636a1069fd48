use hush_dataset::{Image, write_png_preview};

use crate::TempDir;

#[test]
fn preview_is_8_bit_srgb_with_exposure_and_clamping() {
    let dir = TempDir::new("png");
    let path = dir.join("preview.png");
    // Pixels: 0.25 (× exposure 2 = 0.5), 1.0 (clamped), NaN, 0, -1.
    let values = [0.25f32, 1.0, f32::NAN, 0.0, -1.0];
    let im = Image::from_fn(5, 1, 3, |x, _, _| values[x]);
    write_png_preview(&path, &im, 2.0).unwrap();
    assert_eq!(dir.files(), ["preview.png"]);

    let png = image::open(&path).unwrap();
    assert_eq!(png.color(), image::ColorType::Rgb8);
    let rgb = png.to_rgb8();
    // sRGB(0.5) = 1.055 · 0.5^(1/2.4) − 0.055 = 0.7354 → 187.5 → 188.
    let expected = [188u8, 255, 0, 0, 0];
    for (x, e) in expected.iter().enumerate() {
        assert_eq!(rgb.get_pixel(x as u32, 0).0, [*e; 3], "pixel {x}");
    }
}

#[test]
fn grey_images_are_replicated_and_two_channels_refused() {
    let dir = TempDir::new("png-grey");
    write_png_preview(dir.join("g.png"), &Image::from_fn(2, 2, 1, |_, _, _| 1.0), 1.0).unwrap();
    assert_eq!(image::open(dir.join("g.png")).unwrap().to_rgb8().get_pixel(1, 1).0, [255; 3]);
    assert!(write_png_preview(dir.join("bad.png"), &Image::zeros(2, 2, 2), 1.0).is_err());
    assert_eq!(dir.files(), ["g.png"]);
}
