use hush_net::transfer::{Transfer, pu_forward};
use hush_net::{Feature, InputFeatures, build_input, finish_color, prepare_color};

#[test]
fn features_parse_and_print() {
    let f = InputFeatures::parse("diff,spec,nrm").unwrap();
    assert_eq!(f.aux, vec![Feature::Diffuse, Feature::Specular, Feature::Normal]);
    assert_eq!(f.in_channels(), 12);
    assert_eq!(f.to_string(), "hdr,diff,spec,nrm");
    assert_eq!(InputFeatures::parse(&f.to_string()).unwrap(), f);
    assert_eq!(InputFeatures::parse("albedo, normal").unwrap().to_string(), "hdr,alb,nrm");
    assert_eq!(InputFeatures::parse("").unwrap().in_channels(), 3);
    assert!(InputFeatures::parse("alb,alb").unwrap_err().to_string().contains("twice"));
    assert!(InputFeatures::parse("depth").unwrap_err().to_string().contains("depth"));
    assert_eq!(serde_json::to_string(&f).unwrap(), r#"{"aux":["diffuse","specular","normal"]}"#);
}

/// OIDN's input processing: color × exposure → PU → ≤ 1; albedo-like clamped to [0, 1]; normals clamped
/// to [-1, 1] and mapped to [0, 1]; NaN → 0. Channels: color, then the features in order.
#[test]
fn build_input_prepares_each_feature_like_oidn() {
    let features = InputFeatures::new(vec![Feature::Normal, Feature::Diffuse]).unwrap();
    // Two pixels (2×1).
    let color = [1.0, f32::NAN, -3.0, 1e9, 0.5, 2.0];
    let normal = [-1.0, 0.0, 1.0, 2.0, f32::NAN, -0.5];
    let diffuse = [0.25, 1.5, -0.1, f32::NAN, 0.0, 1.0];
    let x = build_input(&features, 2, 1, &color, &[&normal, &diffuse], 2.0, Transfer::Pu).unwrap();
    assert_eq!(x.len(), 2 * 9);
    let expected = [
        pu_forward(2.0),
        0.0,
        0.0,
        0.0,
        0.5,
        1.0,
        0.25,
        1.0,
        0.0, // pixel 0
        1.0,
        pu_forward(1.0),
        pu_forward(4.0),
        1.0,
        0.5,
        0.25,
        0.0,
        0.0,
        1.0, // pixel 1
    ];
    for (i, (a, b)) in x.iter().zip(&expected).enumerate() {
        assert!((a - b).abs() < 1e-6, "channel {i}: {a} vs {b}");
    }
    let err = build_input(&features, 2, 1, &color, &[&normal], 2.0, Transfer::Pu).unwrap_err().to_string();
    assert!(err.contains("1 auxiliary images"), "{err}");
    let err = build_input(&features, 3, 1, &color, &[&normal, &diffuse], 2.0, Transfer::Pu).unwrap_err().to_string();
    assert!(err.contains("color has 6 values"), "{err}");
    assert!(build_input(&features, 2, 1, &color, &[&normal, &diffuse], 0.0, Transfer::Pu).is_err());
}

/// The variance feature is the standard error (the square root of the pixel's variance) × exposure through
/// the color's transfer, clamped to [0, 1]: what the network sees of the color's noise, in the color's
/// units. Zero stays zero, NaN and negatives become 0, an overflowed variance (f32::MAX) 1; it is the same
/// for training and inference, whose color clamps differ.
#[test]
fn the_variance_feature_is_the_standard_error_in_the_colors_space() {
    let features = InputFeatures::parse("var").unwrap();
    assert_eq!(features.to_string(), "hdr,var");
    assert_eq!(InputFeatures::parse("color,variance").unwrap(), features);
    let color = [0.5f32; 6];
    let variance = [0.0, 0.09, 4.0, f32::NAN, -1.0, f32::MAX];
    let want = [0.0, pu_forward(2.0 * 0.3), pu_forward(2.0 * 2.0), 0.0, 0.0, 1.0];
    for build in [build_input, hush_net::build_inference_input] {
        let x = build(&features, 2, 1, &color, &[&variance], 2.0, Transfer::Pu).unwrap();
        let got = [x[3], x[4], x[5], x[9], x[10], x[11]];
        for (g, w) in got.iter().zip(&want) {
            assert!((g - w).abs() < 1e-6, "{got:?} against {want:?}");
        }
    }
}

#[test]
fn finish_color_inverts_prepare_color() {
    let rgb = [0.0f32, 1e-4, 0.01, 0.5, 3.0, 1000.0];
    for exposure in [0.05f32, 1.0, 7.0] {
        let back = finish_color(&prepare_color(&rgb, exposure, Transfer::Pu), exposure, Transfer::Pu);
        for (a, b) in rgb.iter().zip(&back) {
            assert!((a - b).abs() <= 1e-4 * a.max(1e-3), "exposure {exposure}: {a} -> {b}");
        }
    }
    // Negative network output is clamped to 0.
    assert_eq!(finish_color(&[-0.5], 1.0, Transfer::Pu), vec![0.0]);
}

/// Exact pixels (variance 0, a positive color) are written back where their whole 3×3 neighbourhood inside the
/// image is exact: the interior of an exact region and its image-border pixels, not its edge against noise;
/// black pixels never; nothing at all where no pixel has a variance (one sample per pixel).
#[test]
fn keep_exact_pixels_writes_back_the_interior_of_exact_regions() {
    use hush_net::keep_exact_pixels;
    let (w, h) = (6usize, 5usize);
    // Exact where x < 4 and y < 4 (a constant sky in the top left, touching the image's top and left border);
    // (0, 0) black with variance 0; noisy elsewhere.
    let exact = |x: usize, y: usize| x < 4 && y < 4;
    let mut color = vec![0.0f32; w * h * 3];
    let mut variance = vec![0.0f32; w * h * 3];
    for y in 0..h {
        for x in 0..w {
            let p = (y * w + x) * 3;
            let black = (x, y) == (0, 0);
            color[p..p + 3].copy_from_slice(if black { &[0.0; 3] } else { &[0.5, 0.6, 0.7] });
            if !exact(x, y) {
                variance[p..p + 3].copy_from_slice(&[1e-3; 3]);
            }
        }
    }
    let mut out = vec![9.0f32; w * h * 3];
    let kept = keep_exact_pixels(&mut out, &color, &variance, w, h).unwrap();
    // Kept: every pixel whose neighbourhood (clipped to the image) lies in x < 4, y < 4 and avoids the black
    // (0, 0): (2, 0), (2, 1), (0, 2), (1, 2), (2, 2); x = 3 touches x = 4, y = 3 touches y = 4.
    let want: Vec<(usize, usize)> = (0..h)
        .flat_map(|y| (0..w).map(move |x| (x, y)))
        .filter(|&(x, y)| {
            let near = |dx: i64, dy: i64| {
                let (nx, ny) = (x as i64 + dx, y as i64 + dy);
                nx < 0
                    || ny < 0
                    || nx >= w as i64
                    || ny >= h as i64
                    || (exact(nx as usize, ny as usize) && (nx, ny) != (0, 0))
            };
            (-1..=1).all(|dy| (-1..=1).all(|dx| near(dx, dy)))
        })
        .collect();
    assert_eq!(want, vec![(2, 0), (2, 1), (0, 2), (1, 2), (2, 2)], "the test's own expectation");
    assert_eq!(kept, want.len());
    for y in 0..h {
        for x in 0..w {
            let p = (y * w + x) * 3;
            let expected: &[f32] = if want.contains(&(x, y)) { &color[p..p + 3] } else { &[9.0; 3] };
            assert_eq!(&out[p..p + 3], expected, "pixel ({x}, {y})");
        }
    }
    // One sample per pixel: no variance anywhere, nothing kept.
    let mut untouched = vec![9.0f32; w * h * 3];
    assert_eq!(keep_exact_pixels(&mut untouched, &color, &vec![0.0; w * h * 3], w, h).unwrap(), 0);
    assert!(untouched.iter().all(|&v| v == 9.0));
    let err = keep_exact_pixels(&mut out, &color, &variance[3..], w, h).unwrap_err().to_string();
    assert!(err.contains("6x5"), "{err}");
}

/// Blending the input back: where the pixel's window has variance s² and the denoised level is L, the input's
/// weight is τ²L²/(τ²L² + s²) (one half where s = τL); the window averages the variance (a lone noisy pixel
/// gives its neighbours a 25th of its own over a whole 5×5 window); s² = 0, a black output or a non-finite
/// color leave the network's pixel; no variance anywhere (one sample per pixel) changes nothing; a size
/// mismatch or a τ ≤ 0 is an error.
#[test]
fn blend_input_weighs_the_input_by_its_standard_error() {
    use hush_net::blend_input;
    let (w, h) = (9usize, 7usize);
    let (tau, level) = (0.1f32, 2.0f32);
    let s2 = (tau * level).powi(2); // weight one half
    let color = vec![1.0f32; w * h * 3];
    let mut variance = vec![s2; w * h * 3];
    let mut out = vec![level; w * h * 3];
    let mean = blend_input(&mut out, &color, &variance, w, h, tau, 2).unwrap();
    assert!((mean - 0.5).abs() < 1e-6, "{mean}");
    assert!(out.iter().all(|&v| (v - 1.5).abs() < 1e-6), "half way between 2 and 1");

    // A lone pixel of variance 25·s² at (4, 3) in a zero field: a pixel whose window (5×5, clipped to the 9×7
    // image) of n pixels holds it has 25·s²/n as its window's mean, so the input's weight 1/(1 + 25/n): one half
    // where the window is whole (x in 2..=6, y in 2..=4); the rest have s² = 0 and are left.
    variance.iter_mut().for_each(|v| *v = 0.0);
    let c = (3 * w + 4) * 3;
    variance[c..c + 3].copy_from_slice(&[25.0 * s2; 3]);
    let mut out = vec![level; w * h * 3];
    blend_input(&mut out, &color, &variance, w, h, tau, 2).unwrap();
    for y in 0..h {
        for x in 0..w {
            let p = (y * w + x) * 3;
            let span = |i: usize, len: usize| (i + 3).min(len) - i.saturating_sub(2);
            let n = (span(x, w) * span(y, h)) as f32;
            let want = if x.abs_diff(4) <= 2 && y.abs_diff(3) <= 2 {
                let weight = 1.0 / (1.0 + 25.0 / n);
                level + weight * (1.0 - level)
            } else {
                level
            };
            assert!((out[p] - want).abs() < 1e-6, "pixel ({x}, {y}): {} against {want}", out[p]);
            if (2..=6).contains(&x) && (2..=4).contains(&y) {
                assert!((out[p] - 1.5).abs() < 1e-6, "a whole window: weight one half");
            }
        }
    }

    // A black output, a NaN color: left as the network made them.
    let mut variance = vec![s2; w * h * 3];
    let mut color = vec![1.0f32; w * h * 3];
    color[3] = f32::NAN;
    let mut out = vec![level; w * h * 3];
    out[6..9].copy_from_slice(&[0.0; 3]);
    blend_input(&mut out, &color, &variance, w, h, tau, 2).unwrap();
    assert_eq!(&out[3..9], &[level, level, level, 0.0, 0.0, 0.0]);
    assert!((out[9] - 1.5).abs() < 1e-6);

    // One sample per pixel: nothing changes.
    let mut untouched = vec![level; w * h * 3];
    assert_eq!(blend_input(&mut untouched, &color, &vec![0.0; w * h * 3], w, h, tau, 2).unwrap(), 0.0);
    assert!(untouched.iter().all(|&v| v == level));
    variance.truncate(3);
    let err = blend_input(&mut out, &color, &variance, w, h, tau, 2).unwrap_err().to_string();
    assert!(err.contains("9x7"), "{err}");
    let err = blend_input(&mut out, &color, &vec![s2; w * h * 3], w, h, 0.0, 2).unwrap_err().to_string();
    assert!(err.contains("positive"), "{err}");
}

/// The square's 8 symmetries: each pose undone gives the image back (a non-square image, so the transpose
/// swaps the sides); pose 1 flips x, pose 2 flips y, pose 4 transposes; the 8 poses of an asymmetric image are
/// 8 different images.
#[test]
fn poses_are_the_eight_symmetries_and_undo() {
    use hush_net::ensemble::{POSES, pose, unpose};
    let (w, h, c) = (5usize, 3usize, 2usize);
    let image: Vec<f32> = (0..w * h * c).map(|i| i as f32).collect();
    let at = |x: usize, y: usize| &image[(y * w + x) * c..][..c];
    let mut seen = Vec::new();
    for k in 0..POSES {
        let (posed, pw, ph) = pose(&image, w, h, c, k);
        assert_eq!((pw, ph), if k & 4 != 0 { (h, w) } else { (w, h) }, "pose {k}");
        assert_eq!(unpose(&posed, pw, ph, c, k), image, "pose {k} undone");
        assert!(!seen.contains(&posed), "pose {k} repeats another");
        seen.push(posed);
    }
    let (flip_x, ..) = pose(&image, w, h, c, 1);
    assert_eq!(&flip_x[..c], at(w - 1, 0));
    let (flip_y, ..) = pose(&image, w, h, c, 2);
    assert_eq!(&flip_y[..c], at(0, h - 1));
    let (transposed, tw, _) = pose(&image, w, h, c, 4);
    // Pixel (x, y) of the transpose is (y, x) of the image: (2, 1) there is (1, 2) here.
    assert_eq!(&transposed[(tw + 2) * c..][..c], at(1, 2));
}

/// Restoring the input's low band where estimates disagree: estimates that agree change nothing (weight 0);
/// on a constant image, estimates that differ by ±d from their mean m, against an input at level a whose
/// variance gives its low band s², move every pixel to m + e²/(e² + s²)·(a − m) with e² their sample
/// variance (the Gaussian keeps constants, and s² = v·(Σ g²)² for a constant variance v); no variance anywhere
/// changes nothing; one estimate, a σ ≤ 0 or a size mismatch are errors.
#[test]
fn restore_low_band_weighs_the_spread_against_the_inputs_noise() {
    use hush_net::ensemble::restore_low_band;
    let (w, h) = (12usize, 9usize);
    let n = w * h * 3;
    let (a, m, d) = (0.5f32, 0.3f32, 0.02f32);
    let color = vec![a; n];
    let sigma = 1.0f32;
    // Σ g² of the normalized 7-tap Gaussian of std 1 (radius 3), squared for the 2-D kernel.
    let g: Vec<f32> = (-3i32..=3).map(|x| (-(x * x) as f32 / 2.0).exp()).collect();
    let sum: f32 = g.iter().sum();
    let g2: f32 = g.iter().map(|v| (v / sum) * (v / sum)).sum::<f32>();
    let e2 = 2.0 * d * d; // two estimates m ± d: sample variance (2·d²)/(2 − 1)
    let v = e2 / (g2 * g2); // the input's low band as uncertain as the spread: weight one half
    let variance = vec![v; n];

    let same = vec![m; n];
    let mut out = same.clone();
    let weight = restore_low_band(&mut out, &[&same, &same], &color, &variance, w, h, sigma).unwrap();
    assert_eq!(weight, 0.0);
    assert!(out.iter().all(|&o| o == m));

    let (lo, hi) = (vec![m - d; n], vec![m + d; n]);
    let mut out = vec![m; n];
    let weight = restore_low_band(&mut out, &[&lo, &hi], &color, &variance, w, h, sigma).unwrap();
    assert!((weight - 0.5).abs() < 1e-4, "{weight}");
    assert!(out.iter().all(|&o| (o - (m + 0.5 * (a - m))).abs() < 1e-4), "{:?}", &out[..3]);

    let mut untouched = vec![m; n];
    assert_eq!(restore_low_band(&mut untouched, &[&lo, &hi], &color, &vec![0.0; n], w, h, sigma).unwrap(), 0.0);
    assert!(untouched.iter().all(|&o| o == m));
    let err = restore_low_band(&mut out, &[&lo], &color, &variance, w, h, sigma).unwrap_err().to_string();
    assert!(err.contains("at least 2"), "{err}");
    let err = restore_low_band(&mut out, &[&lo, &hi], &color, &variance, w, h, 0.0).unwrap_err().to_string();
    assert!(err.contains("sigma"), "{err}");
    let err = restore_low_band(&mut out, &[&lo, &hi[..3]], &color, &variance, w, h, sigma).unwrap_err().to_string();
    assert!(err.contains("12x9"), "{err}");
}
