use hush_dataset::Image;

use crate::ramp;

#[test]
fn new_checks_the_length() {
    assert!(Image::new(2, 3, 3, vec![0.0; 18]).is_ok());
    let err = Image::new(2, 3, 3, vec![0.0; 17]).unwrap_err().to_string();
    assert!(err.contains("17") && err.contains("2x3x3") && err.contains("18"), "{err}");
}

#[test]
fn pixel_crop_and_select() {
    let im = ramp(5, 4, 3, 0.0);
    assert_eq!(im.pixel(2, 1), &[0.5 + 1.5, 0.5 + 1.5 + 0.01, 0.5 + 1.5 + 0.02]);
    let c = im.crop(1, 2, 3, 2).unwrap();
    assert_eq!((c.width, c.height, c.channels), (3, 2, 3));
    assert_eq!(c.pixel(0, 0), im.pixel(1, 2));
    assert_eq!(c.pixel(2, 1), im.pixel(3, 3));
    assert!(im.crop(3, 0, 3, 1).is_err());

    let g = im.select_channels(1..2).unwrap();
    assert_eq!(g.channels, 1);
    assert_eq!(g.pixel(4, 3), &im.pixel(4, 3)[1..2]);
    assert!(im.select_channels(2..4).is_err());
}

#[test]
fn concat_channels_stacks_and_names_both_sizes_on_mismatch() {
    let a = ramp(4, 3, 3, 0.0);
    let b = ramp(4, 3, 1, 100.0);
    let ab = Image::concat_channels(&[&a, &b]).unwrap();
    assert_eq!(ab.channels, 4);
    assert_eq!(&ab.pixel(3, 2)[..3], a.pixel(3, 2));
    assert_eq!(ab.pixel(3, 2)[3], b.pixel(3, 2)[0]);
    assert_eq!(ab.select_channels(0..3).unwrap(), a);

    let small = ramp(4, 2, 3, 0.0);
    let err = Image::concat_channels(&[&a, &small]).unwrap_err().to_string();
    assert!(err.contains("4x3x3") && err.contains("4x2x3"), "{err}");
}

#[test]
fn statistics_and_downsampling() {
    let im = Image::from_fn(4, 2, 2, |x, _, c| if c == 0 { x as f32 } else { 1.0 });
    assert_eq!(im.mean(), vec![1.5, 1.0]);
    let d = im.downsample_box(2).unwrap();
    assert_eq!((d.width, d.height), (2, 1));
    assert_eq!(d.data, vec![0.5, 1.0, 2.5, 1.0]);
    assert!(im.downsample_box(3).is_err());

    let mut bad = im.clone();
    bad.data[3] = f32::NAN;
    bad.data[5] = f32::NEG_INFINITY;
    assert_eq!(bad.count_non_finite(), 2);
}
