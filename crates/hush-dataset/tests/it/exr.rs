use hush_dataset::{Image, read_exr, read_rgb, write_exr};

use crate::{TempDir, ramp, shared_reference};

#[test]
fn round_trip_with_several_layers() {
    let dir = TempDir::new("exr-round-trip");
    let path = dir.join("layers.exr");
    let color = ramp(7, 5, 3, 0.0);
    let albedo = ramp(7, 5, 3, 0.5);
    let normal = Image::from_fn(7, 5, 3, |x, _, c| if c == 0 { -(x as f32) / 7.0 } else { 0.5 });
    let depth = ramp(7, 5, 1, 3.0);
    write_exr(&path, &[("", &color), ("albedo", &albedo), ("normal", &normal), ("depth", &depth)]).unwrap();

    let exr = read_exr(&path).unwrap();
    assert_eq!((exr.width, exr.height), (7, 5));
    let names: Vec<&str> = exr.channels.keys().map(String::as_str).collect();
    assert_eq!(
        names,
        ["B", "G", "R", "albedo.B", "albedo.G", "albedo.R", "depth.Y", "normal.X", "normal.Y", "normal.Z"]
    );
    // f32 samples, lossless compression: bit-exact.
    assert_eq!(exr.layer("").unwrap(), color);
    assert_eq!(exr.layer("albedo").unwrap(), albedo);
    assert_eq!(exr.layer("normal").unwrap(), normal);
    assert_eq!(exr.layer("depth").unwrap(), depth);
    assert_eq!(read_rgb(&path).unwrap(), color);
    assert_eq!(dir.files(), ["layers.exr"], "no temporary file is left behind");
}

#[test]
fn missing_layer_lists_the_available_channels() {
    let dir = TempDir::new("exr-missing");
    let path = dir.join("rgb.exr");
    write_exr(&path, &[("", &ramp(2, 2, 3, 0.0))]).unwrap();
    let err = read_exr(&path).unwrap().layer("specular").unwrap_err().to_string();
    assert!(err.contains("rgb.exr") && err.contains("specular.R") && err.contains("B, G, R"), "{err}");
}

#[test]
fn layers_of_different_sizes_are_refused_and_nothing_is_written() {
    let dir = TempDir::new("exr-sizes");
    let path = dir.join("bad.exr");
    let err = write_exr(&path, &[("", &ramp(4, 4, 3, 0.0)), ("albedo", &ramp(4, 3, 3, 0.0))]).unwrap_err().to_string();
    assert!(err.contains("4x3x3") && err.contains("4x4x3") && err.contains("albedo"), "{err}");
    assert!(dir.files().is_empty());

    let err = write_exr(&path, &[("normal", &ramp(4, 4, 2, 0.0))]).unwrap_err().to_string();
    assert!(err.contains("normal") && err.contains('2'), "{err}");
}

#[test]
fn half_samples_are_converted_to_f32() {
    use exr::prelude::*;
    let dir = TempDir::new("exr-half");
    let path = dir.join("half.exr");
    let values = [0.0f32, 0.5, 1.0, 2.0, 65504.0, 1e-3];
    let channel = |name: &str, k: usize| {
        AnyChannel::new(name, FlatSamples::F16(values.iter().map(|v| f16::from_f32(v + k as f32)).collect()))
    };
    let channels = AnyChannels::sort(SmallVec::from_vec(vec![channel("R", 0), channel("G", 1), channel("B", 2)]));
    exr::prelude::Image::from_channels((3, 2), channels).write().to_file(&path).unwrap();

    let im = read_rgb(&path).unwrap();
    assert_eq!((im.width, im.height, im.channels), (3, 2, 3));
    for (i, v) in values.iter().enumerate() {
        for k in 0..3 {
            let expected = f16::from_f32(v + k as f32).to_f32();
            assert_eq!(im.data[i * 3 + k], expected);
        }
    }
}

#[test]
fn reads_the_mitsuba_reference() {
    let dir = shared_reference("mitsuba-cbox");
    let exr = read_exr(dir.join("mitsuba_3156spp.exr")).unwrap();
    assert_eq!((exr.width, exr.height), (512, 512));
    assert_eq!(exr.channels.keys().collect::<Vec<_>>(), ["B", "G", "R"]);
    let reference = exr.layer("").unwrap();
    assert_eq!(reference.count_non_finite(), 0);
    let noisy = read_rgb(dir.join("mitsuba_16spp.exr")).unwrap();

    // Both are unbiased estimates of the same image: channel means agree closely.
    let (m_ref, m_noisy) = (reference.mean(), noisy.mean());
    for c in 0..3 {
        assert!(m_ref[c] > 0.05 && m_ref[c] < 5.0, "implausible mean {m_ref:?}");
        let rel = (m_noisy[c] - m_ref[c]).abs() / m_ref[c];
        assert!(rel < 0.02, "channel {c}: 16 spp mean {} vs reference {}", m_noisy[c], m_ref[c]);
    }
    // Red wall on the left, green wall on the right (see the README beside the files).
    let (left, right) = (reference.pixel(40, 256), reference.pixel(471, 256));
    assert!(left[0] > 2.0 * left[1] && right[1] > 2.0 * right[0], "left {left:?} right {right:?}");
}

#[test]
fn reads_the_oidn_normal_input_as_plain_rgb() {
    let normal = read_rgb(shared_reference("oidn-2.5.1").join("input_normal.exr")).unwrap();
    assert_eq!((normal.width, normal.height, normal.channels), (512, 512, 3));
    assert!(normal.data.iter().all(|v| v.abs() <= 1.0 + 1e-3), "normals outside [-1, 1]");
}

#[test]
fn missing_file_names_the_path() {
    let err = read_exr("/nonexistent/dir/x.exr").unwrap_err().to_string();
    assert!(err.contains("/nonexistent/dir/x.exr") && err.contains("no such file"), "{err}");
}

/// "no such file" only of a path that does not exist: a folder or a device is named as what it is.
#[test]
fn a_folder_or_device_is_not_called_missing() {
    let dir = std::env::temp_dir().join(format!("hush-exr-folder-{}", std::process::id()));
    let folder = dir.join("image.exr");
    std::fs::create_dir_all(&folder).unwrap();
    let err = read_exr(&folder).unwrap_err().to_string();
    assert!(err.contains("is a directory") && !err.contains("no such file"), "{err}");
    let err = read_exr("/dev/zero").unwrap_err().to_string();
    assert!(err.contains("not a regular file") && !err.contains("no such file"), "{err}");
    let check = hush_dataset::check_image(&folder, 2, 2).unwrap_err();
    assert!(check.contains("is a directory") && !check.contains("missing"), "{check}");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// An EXR file whose header claims a huge image (its data window patched to 65535×65535 in a 2×2 file of a
/// few hundred bytes) is refused from its header, before the decoder allocates 51 GB; the error names the
/// file, what it declares and how to raise the limit.
#[test]
fn a_header_that_claims_a_huge_image_is_refused_before_decoding() {
    let dir = TempDir::new("exr-huge");
    let path = dir.path().join("huge.exr");
    write_exr(&path, &[("", &ramp(2, 2, 3, 0.5))]).unwrap();
    let mut bytes = std::fs::read(&path).unwrap();
    let at = bytes.windows(16).position(|w| w == b"dataWindow\0box2i").expect("a data window") + 17 + 4;
    for (i, v) in [0i32, 0, 65534, 65534].iter().enumerate() {
        bytes[at + 4 * i..at + 4 * i + 4].copy_from_slice(&v.to_le_bytes());
    }
    std::fs::write(&path, &bytes).unwrap();
    let err = read_exr(&path).unwrap_err().to_string();
    assert!(err.contains("huge.exr") && err.contains("65535x65535 with 3 channels"), "{err}");
    assert!(err.contains("HUSH_MAX_EXR_SAMPLES"), "{err}");
    // The real file is far below the limit.
    write_exr(&path, &[("", &ramp(2, 2, 3, 0.5))]).unwrap();
    assert_eq!(hush_dataset::check_exr_header(&path).unwrap(), 12);
}
