use hush_dataset::Image;
use hush_eval::pictures::{HIGH_COLOR, LOW_COLOR, MARK_HIGH, MARK_LOW, Rgb8, error_marks, worst_window};
use hush_eval::tonemap;

/// Each pixel is classified by its largest tonemapped channel difference: ≤ 3 % grey, ≤ 10 % yellow,
/// above red; the fractions count them.
#[test]
fn error_marks_color_pixels_by_threshold() {
    let reference = Image::from_fn(8, 4, 3, |_, _, _| 0.2);
    // A ramp of relative errors across the image, in the green channel only.
    let test =
        Image::from_fn(8, 4, 3, |x, y, c| if c == 1 { 0.2 * (1.0 + 0.1 * (x + 8 * y) as f32 / 4.0) } else { 0.2 });
    let (picture, marks) = error_marks(&test, &reference, 1.0).unwrap();
    let (t, r) = (tonemap(&test, 1.0), tonemap(&reference, 1.0));
    let (mut low, mut high) = (0, 0);
    for i in 0..32 {
        let off = (t.data[3 * i + 1] - r.data[3 * i + 1]).abs();
        let color = &picture.data[3 * i..3 * i + 3];
        if off > MARK_HIGH {
            high += 1;
            assert_eq!(color, HIGH_COLOR, "pixel {i} off by {off}");
        } else if off > MARK_LOW {
            low += 1;
            assert_eq!(color, LOW_COLOR, "pixel {i} off by {off}");
        } else {
            assert!(color[0] == color[1] && color[1] == color[2], "pixel {i} off by {off} is grey");
        }
    }
    assert!(low > 0 && high > 0 && low + high < 32, "the ramp crosses both thresholds: {low} {high}");
    assert_eq!(marks.over_high, f64::from(high) / 32.0);
    assert_eq!(marks.over_low, f64::from(low + high) / 32.0);
}

#[test]
fn worst_window_finds_the_noisy_patch() {
    let reference = Image::from_fn(64, 48, 3, |_, _, _| 0.3);
    let mut test = reference.clone();
    for y in 30..38 {
        for x in 40..48 {
            test.pixel_mut(x, y)[0] = if (x + y) % 2 == 0 { 2.0 } else { 0.0 };
        }
    }
    let (x, y) = worst_window(&test, &reference, 1.0, 16).unwrap();
    assert!(x <= 40 && x + 16 >= 48 && y <= 30 && y + 16 >= 38, "window at ({x}, {y})");
}

#[test]
fn crop_and_upscale_keep_pixels() {
    let image = Image::from_fn(4, 3, 3, |x, y, _| (x + 4 * y) as f32 / 12.0);
    let p = Rgb8::tonemapped(&image, 1.0).unwrap();
    let c = p.crop(1, 1, 2, 5);
    assert_eq!((c.width, c.height), (2, 2), "clipped to the picture");
    assert_eq!(&c.data[..3], &p.data[3 * 5..3 * 6]);
    let u = c.upscale(3);
    assert_eq!((u.width, u.height), (6, 6));
    assert_eq!(&u.data[3 * (6 * 2 + 2)..3 * (6 * 2 + 3)], &c.data[..3]);
    let png = u.to_png().unwrap();
    assert_eq!(&png[1..4], b"PNG");
}
