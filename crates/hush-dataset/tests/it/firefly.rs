use hush_dataset::{Image, despeckle, luminance};

/// A flat grey image with ±2 % deterministic noise, like a converged reference.
fn grey(w: usize, h: usize) -> Image {
    Image::from_fn(w, h, 3, |x, y, c| 0.5 * (1.0 + 0.02 * (((x * 7 + y * 13 + c * 3) % 11) as f32 / 5.0 - 1.0)))
}

#[test]
fn a_firefly_is_clamped_to_factor_times_its_brightest_neighbour() {
    let mut im = grey(16, 16);
    im.pixel_mut(5, 7).copy_from_slice(&[900.0, 1000.0, 1100.0]);
    let before = im.clone();
    let stats = despeckle(&mut im, 4.0).unwrap();
    assert_eq!(stats.clamped_pixels, 1);
    let max_neighbour = [(4, 6), (5, 6), (6, 6), (4, 7), (6, 7), (4, 8), (5, 8), (6, 8)]
        .iter()
        .map(|&(x, y)| luminance(before.pixel(x, y)))
        .fold(0.0f32, f32::max);
    let l = luminance(im.pixel(5, 7));
    assert!((l - 4.0 * max_neighbour).abs() < 1e-4, "clamped to {l}, 4 × {max_neighbour} expected");
    // Chromaticity is kept: the ratios of the channels are unchanged.
    let p = im.pixel(5, 7);
    assert!((p[0] / p[1] - 0.9).abs() < 1e-5 && (p[2] / p[1] - 1.1).abs() < 1e-5, "{p:?}");
    // Nothing else changed; the removed energy is the firefly's excess.
    for y in 0..16 {
        for x in 0..16 {
            if (x, y) != (5, 7) {
                assert_eq!(im.pixel(x, y), before.pixel(x, y), "pixel ({x}, {y}) changed");
            }
        }
    }
    let total: f64 = before.data.chunks_exact(3).map(|p| f64::from(luminance(p))).sum();
    let removed = f64::from(luminance(before.pixel(5, 7)) - l);
    assert!((stats.energy_removed - removed / total).abs() < 1e-6, "{stats:?}");
    assert!(stats.energy_removed > 0.8, "the firefly held most of the image's energy: {stats:?}");
}

#[test]
fn lights_edges_and_lines_are_not_fireflies() {
    let mut im = grey(16, 16);
    // A 3×3 emitter, a one-pixel-wide bright line and a bright corner pixel of the image.
    for y in 2..5 {
        for x in 2..5 {
            im.pixel_mut(x, y).copy_from_slice(&[50.0, 50.0, 50.0]);
        }
    }
    for x in 0..16 {
        im.pixel_mut(x, 10).copy_from_slice(&[20.0, 20.0, 20.0]);
    }
    let before = im.clone();
    let stats = despeckle(&mut im, 4.0).unwrap();
    assert_eq!(stats.clamped_pixels, 0);
    assert_eq!(im, before);
    assert_eq!(despeckle(&mut im, f32::INFINITY).unwrap().clamped_pixels, 0);
}

#[test]
fn despeckle_handles_borders_and_rejects_bad_input() {
    let mut im = Image::zeros(3, 2, 3);
    im.pixel_mut(0, 0).copy_from_slice(&[1.0, 1.0, 1.0]);
    let stats = despeckle(&mut im, 4.0).unwrap();
    assert_eq!(stats.clamped_pixels, 1, "a lit pixel among black neighbours is a firefly");
    assert_eq!(im.pixel(0, 0), &[0.0, 0.0, 0.0]);
    assert_eq!(stats.energy_removed, 1.0);
    assert!(despeckle(&mut Image::zeros(4, 4, 1), 4.0).is_err());
    assert!(despeckle(&mut grey(4, 4), 0.5).is_err());
    assert_eq!(despeckle(&mut Image::zeros(1, 1, 3), 4.0).unwrap().clamped_pixels, 0);
}
