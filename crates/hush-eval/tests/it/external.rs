//! External Python baselines (`hush_eval::external`): the npy interchange, the skipped outcome, the inverse
//! tonemap, and — when `cargo xtask baselines setup` has installed the venv — BM3D and OIDN for real.

use std::path::{Path, PathBuf};

use hush_dataset::Image;
use hush_eval::external::{
    BM3D_SIGMA_FACTOR, Baseline, INSTALL, Input, Outcome, bm3d_sigma, inverse_tonemap, read_npy, run_baseline,
    venv_python, write_npy,
};
use hush_eval::{compare, exposure_of, tonemap};

use crate::TempDir;
use crate::guided::cbox_crop;

#[test]
fn npy_round_trips_and_rejects_other_files() {
    let dir = TempDir::new("npy");
    let im = Image::from_fn(5, 3, 3, |x, y, c| (x * 100 + y * 10 + c) as f32 - 0.5);
    let path = dir.path().join("a.npy");
    write_npy(&path, &im).unwrap();
    let bytes = std::fs::read(&path).unwrap();
    assert_eq!(&bytes[..8], b"\x93NUMPY\x01\x00");
    assert_eq!((10 + u16::from_le_bytes([bytes[8], bytes[9]]) as usize) % 64, 0, "header is 64-byte aligned");
    let back = read_npy(&path).unwrap();
    assert_eq!((back.width, back.height, back.channels), (5, 3, 3));
    assert_eq!(back.data, im.data);

    std::fs::write(dir.path().join("b.npy"), b"not numpy").unwrap();
    let err = read_npy(&dir.path().join("b.npy")).unwrap_err().to_string();
    assert!(err.contains("b.npy") && err.contains("magic"), "{err}");
    let mut f64_header = bytes.clone();
    let at = f64_header.windows(3).position(|w| w == b"<f4").unwrap();
    f64_header[at..at + 3].copy_from_slice(b"<f8");
    std::fs::write(dir.path().join("c.npy"), &f64_header).unwrap();
    let err = read_npy(&dir.path().join("c.npy")).unwrap_err().to_string();
    assert!(err.contains("c.npy") && err.contains("float32"), "{err}");
    let err = read_npy(&dir.path().join("missing.npy")).unwrap_err().to_string();
    assert!(err.contains("missing.npy"), "{err}");
}

#[test]
fn inverse_tonemap_undoes_tonemap_below_white() {
    let im = Image::from_fn(16, 8, 3, |x, y, c| 0.001 * ((x + 16 * y) * 3 + c) as f32 * 1.05f32.powi(x as i32));
    let exposure = exposure_of(&im).unwrap();
    let back = inverse_tonemap(&tonemap(&im, exposure), exposure);
    for (a, b) in im.data.iter().zip(&back.data) {
        // The tonemap is stored in f32 (≈ 6e-8 absolute after sRGB); inverting it amplifies that by the curve's
        // slope, at most a few 1e-4 relative in the shoulder below the white point.
        if a * exposure < 5.0 {
            assert!((a - b).abs() <= 1e-3 * a.abs() + 1e-6, "{a} -> {b}");
        }
    }
}

#[test]
fn missing_venv_or_package_is_skipped_with_the_install_command() {
    let (color, albedo, normal) = small_inputs();
    let inputs = [Input { color: &color, albedo: Some(&albedo), normal: Some(&normal) }];
    let nowhere = Path::new("/nonexistent/baselines-venv/bin/python");
    for baseline in [Baseline::Bm3d, Baseline::Oidn] {
        match run_baseline(baseline, &inputs, nowhere, 1).unwrap() {
            Outcome::Skipped { reason, install } => {
                assert_eq!(install, INSTALL);
                assert!(reason.contains(baseline.name()) && reason.contains("baselines-venv/bin/python"), "{reason}");
                assert!(!reason.contains("/nonexistent"), "no machine path: {reason}");
            }
            Outcome::Done { .. } => panic!("ran without a Python"),
        }
    }
    // A Python whose packages are missing: the runner exits with code 3 and names the module.
    #[cfg(unix)]
    {
        let dir = TempDir::new("fake-python");
        let missing = fake_python(&dir, "missing", "echo '{\"missing\": \"bm3d\"}' > \"$2/result.json\"; exit 3");
        match run_baseline(Baseline::Bm3d, &inputs, &missing, 1).unwrap() {
            Outcome::Skipped { reason, install } => {
                assert_eq!(install, INSTALL);
                assert!(reason.contains("`bm3d` is not installed"), "{reason}");
            }
            Outcome::Done { .. } => panic!("a missing package was not reported as skipped"),
        }
        // Any other failure is an error that carries the runner's standard error.
        let broken = fake_python(&dir, "broken", "echo 'Traceback: out of memory' >&2; exit 1");
        let err = run_baseline(Baseline::Oidn, &inputs, &broken, 1).unwrap_err().to_string();
        assert!(err.contains("oidn baseline") && err.contains("out of memory"), "{err}");
        // A runner that exits 0 without writing its result is an error naming result.json.
        let silent = fake_python(&dir, "silent", "exit 0");
        let err = run_baseline(Baseline::Oidn, &inputs, &silent, 1).unwrap_err().to_string();
        assert!(err.contains("result.json"), "{err}");
    }
    // Nothing to do is not a skip either.
    assert!(
        matches!(run_baseline(Baseline::Bm3d, &[], nowhere, 1).unwrap(), Outcome::Done { images, .. } if images.is_empty())
    );
    // Bad input is an error, not a skip.
    let mut nan = color.clone();
    nan.pixel_mut(1, 1)[0] = f32::NAN;
    let bad = [Input { color: &nan, albedo: None, normal: None }];
    let err = run_baseline(Baseline::Oidn, &bad, nowhere, 1).unwrap_err().to_string();
    assert!(err.contains("input 0 color") && err.contains("(x 1, y 1)"), "{err}");
    let wrong = Image::zeros(3, 3, 3);
    let bad = [Input { color: &color, albedo: Some(&wrong), normal: None }];
    assert!(run_baseline(Baseline::Oidn, &bad, nowhere, 1).unwrap_err().to_string().contains("albedo"));
}

#[test]
fn bm3d_sigma_follows_the_noise() {
    let mut rng = crate::guided::Rng::new(5);
    let flat = Image::from_fn(64, 64, 3, |_, _, _| 0.5);
    assert_eq!(bm3d_sigma(&flat), 0.0);
    // Gaussian-ish noise of std 0.05 (sum of 12 uniforms): MAD recovers ≈ 0.05 (within 15 % on 32² blocks).
    let noisy = Image::from_fn(64, 64, 3, |_, _, _| 0.5 + 0.05 * ((0..12).map(|_| rng.uniform()).sum::<f32>() - 6.0));
    let sigma = bm3d_sigma(&noisy);
    assert!((sigma / (BM3D_SIGMA_FACTOR * 0.05) - 1.0).abs() < 0.15, "{sigma}");
}

fn small_inputs() -> (Image, Image, Image) {
    let color = Image::from_fn(16, 16, 3, |x, y, c| 0.1 + 0.02 * (x + y + c) as f32);
    let albedo = Image::from_fn(16, 16, 3, |_, _, _| 0.5);
    let normal = Image::from_fn(16, 16, 3, |_, _, c| [0.0, 0.0, 1.0][c]);
    (color, albedo, normal)
}

/// An executable shell script standing in for the venv's Python: `$1` is the runner script, `$2` the job dir.
#[cfg(unix)]
fn fake_python(dir: &TempDir, name: &str, body: &str) -> PathBuf {
    use std::os::unix::fs::PermissionsExt;
    let path = dir.path().join(name);
    std::fs::write(&path, format!("#!/bin/sh\n{body}\n")).unwrap();
    std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o755)).unwrap();
    path
}

/// With the venv installed (`cargo xtask baselines setup`), BM3D and OIDN run on a 64² crop of the 16-spp
/// Cornell box and lower its error; without it, both are skipped. `HUSH_REQUIRE_BASELINES=1` (set by
/// `cargo xtask baselines check`) turns a skip into a failure.
#[test]
fn run_for_real_when_installed() {
    let require = std::env::var_os("HUSH_REQUIRE_BASELINES").is_some_and(|v| v == "1");
    let python = venv_python();
    let (color, albedo, normal, reference) = cbox_crop(200, 300, 64);
    let before = compare(&color, &reference).unwrap();
    let inputs = [Input { color: &color, albedo: Some(&albedo), normal: Some(&normal) }];
    for baseline in [Baseline::Bm3d, Baseline::Oidn] {
        match run_baseline(baseline, &inputs, &python, 1).unwrap() {
            Outcome::Skipped { reason, install } => {
                assert!(!require, "{reason} (install: {install})");
                assert!(!python.is_file() || reason.contains("is not installed"), "{reason}");
                eprintln!("skipped: {reason}; install: {install}");
            }
            Outcome::Done { images, seconds, versions } => {
                let after = compare(&images[0], &reference).unwrap();
                eprintln!(
                    "{}: PSNR {:.2} -> {:.2} dB, SSIM {:.4} -> {:.4}, {:.4} s/image (warm median), {versions}",
                    baseline.name(),
                    before.psnr,
                    after.psnr,
                    before.ssim,
                    after.ssim,
                    seconds[0]
                );
                assert_eq!(seconds.len(), 1);
                assert!(seconds[0] > 0.0 && seconds[0].is_finite());
                // Both are far better than 16 spp here (OIDN by > 10 dB on the full image): 3 dB is a floor.
                assert!(after.psnr > before.psnr + 3.0, "{}: {} -> {}", baseline.name(), before.psnr, after.psnr);
            }
        }
    }
}

/// In-process OIDN (feature `oidn`) reproduces OIDN 2.5.1's own output in shared/reference/oidn-2.5.1.
#[cfg(feature = "oidn")]
#[test]
fn oidn_native_reproduces_the_shared_outputs() {
    use hush_dataset::read_rgb;

    let dir = crate::shared_reference("oidn-2.5.1");
    let read = |name: &str| read_rgb(dir.join(name)).unwrap();
    let (color, albedo, normal) = (read("input_color.exr"), read("input_albedo.exr"), read("input_normal.exr"));
    for (features, want) in [(true, "oidn_rt_hdr_alb_nrm.exr"), (false, "oidn_rt_hdr.exr")] {
        let (a, n) = if features { (Some(&albedo), Some(&normal)) } else { (None, None) };
        let (out, seconds) = hush_eval::oidn_native::denoise(&color, a, n, 1).unwrap();
        let want = read(want);
        // The same library and weights on the same CPU: the anchors measured bit-identical output; allow
        // 1e-5 relative for a different SIMD path on another CPU.
        let worst = out.data.iter().zip(&want.data).map(|(x, y)| (x - y).abs() / (y.abs() + 1e-3)).fold(0.0, f32::max);
        eprintln!("in-process OIDN ({features}): {seconds:.3} s warm, worst relative difference {worst:e}");
        assert!(worst < 1e-5, "{worst}");
    }
}

/// OIDN's own runtime runs weights that are not its own as hush does: OIDN's `rt_hdr_alb_nrm` (`unet`) and
/// `rt_hdr_calb_cnrm_large` (`unet_large`, which OIDN's runtime recognizes by its tensors), with every weight
/// changed by up to ±3 % (deterministically), written as TZA the way `hush export` writes a hush model,
/// denoise a 64² Cornell box crop within 45 dB of hush's output for the same file, and visibly unlike OIDN's
/// built-in weights (so the file was used). Skipped without the venv, like the test above.
#[test]
fn oidn_runtime_runs_other_weights_as_hush_does() {
    use hush_net::{Net, load_tza, parse_tza, write_tza};

    let require = std::env::var_os("HUSH_REQUIRE_BASELINES").is_some_and(|v| v == "1");
    let python = venv_python();
    let (color, albedo, normal, _) = cbox_crop(200, 300, 64);
    let inputs = [Input { color: &color, albedo: Some(&albedo), normal: Some(&normal) }];
    for name in ["rt_hdr_alb_nrm", "rt_hdr_calb_cnrm_large"] {
        let official = std::fs::read(
            Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("../../data/weights/oidn-2.5.1/{name}.tza")),
        )
        .unwrap();
        let mut tensors = parse_tza(&official).unwrap();
        for (t, tensor) in tensors.iter_mut().enumerate() {
            for (i, v) in tensor.values.iter_mut().enumerate() {
                let wobble = (((i * 7919 + t * 104_729) % 601) as f32 / 300.0 - 1.0) * 0.03;
                *v *= 1.0 + wobble;
            }
        }
        let weights = write_tza(&tensors).unwrap();
        let theirs = match hush_eval::external::run_oidn_with_weights(&inputs, &weights, &python, 1).unwrap() {
            Outcome::Skipped { reason, install } => {
                assert!(!require, "{reason} (install: {install})");
                eprintln!("skipped: {reason}; install: {install}");
                return;
            }
            Outcome::Done { images, .. } => images.into_iter().next().unwrap(),
        };
        let (net, info) = load_tza(&weights, None, &candle_core::Device::Cpu).unwrap();
        let aux = [albedo.data.as_slice(), normal.data.as_slice()];
        let ours = hush_net::denoise(&Net::from(net), &info, color.width, color.height, &color.data, &aux).unwrap();
        let ours = Image::new(color.width, color.height, 3, ours).unwrap();
        let agreement = hush_eval::psnr(&theirs, &ours).unwrap();
        let Outcome::Done { images, .. } = run_baseline(Baseline::Oidn, &inputs, &python, 1).unwrap() else {
            panic!("OIDN ran with weights but not without")
        };
        let from_built_in = hush_eval::psnr(&theirs, &images[0]).unwrap();
        eprintln!(
            "{name}: OIDN's runtime with the file vs hush: {agreement:.1} dB; vs OIDN's built-in weights: \
             {from_built_in:.1} dB"
        );
        assert!(agreement >= 45.0, "{name}: {agreement:.1} dB");
        assert!(from_built_in < agreement - 5.0, "{name}: the weights file made no difference: {from_built_in:.1} dB");
    }
}
