use hush_dataset::{read_pfm, write_pfm};

use crate::{TempDir, ramp};

/// RGB and one-channel images survive a write and a read bit for bit, and the file is OIDN's layout:
/// little-endian (negative scale), rows from the bottom up.
#[test]
fn round_trip_and_layout() {
    let dir = TempDir::new("pfm-round-trip");
    for channels in [3, 1] {
        let path = dir.join(&format!("image{channels}.pfm"));
        let image = ramp(5, 3, channels, 0.25);
        write_pfm(&path, &image).unwrap();
        assert_eq!(read_pfm(&path).unwrap(), image);
        let bytes = std::fs::read(&path).unwrap();
        let header = if channels == 3 { "PF\n5 3\n-1.0\n" } else { "Pf\n5 3\n-1.0\n" };
        assert!(bytes.starts_with(header.as_bytes()));
        // The first sample in the file is the bottom row's first.
        let first = f32::from_le_bytes(bytes[header.len()..][..4].try_into().unwrap());
        assert_eq!(first, image.data[2 * 5 * channels]);
    }
    assert_eq!(dir.files(), ["image1.pfm", "image3.pfm"], "no temporary file is left behind");
}

/// A big-endian file (positive scale) written by another tool reads the same.
#[test]
fn reads_big_endian() {
    let dir = TempDir::new("pfm-big-endian");
    let path = dir.join("be.pfm");
    let mut bytes = b"Pf\n2 1\n1.0\n".to_vec();
    for v in [1.5f32, -2.0] {
        bytes.extend(v.to_be_bytes());
    }
    std::fs::write(&path, bytes).unwrap();
    assert_eq!(read_pfm(&path).unwrap().data, [1.5, -2.0]);
}

/// Malformed files are refused with the file's name and what is wrong.
#[test]
fn malformed_files_name_the_file_and_the_fault() {
    let dir = TempDir::new("pfm-malformed");
    for (name, bytes, says) in [
        ("magic.pfm", b"P6\n1 1\n-1.0\n\0\0\0\0".to_vec(), "magic"),
        ("short.pfm", b"PF\n2 2\n-1.0\n\0\0\0\0".to_vec(), "needs 48 bytes"),
        ("size.pfm", b"PF\n0 2\n-1.0\n".to_vec(), "width \"0\""),
        ("header.pfm", b"PF\n2".to_vec(), "header ends"),
        // Hostile headers: a size whose product overflows, one far beyond the limit with no data, a side
        // written as a float, a NaN scale, and a header that ends without the byte before the samples.
        ("overflow.pfm", b"PF\n4294967296 4294967296\n-1.0\n".to_vec(), "above the limit"),
        ("huge.pfm", b"PF\n65535 65535\n-1.0\n".to_vec(), "above the limit"),
        ("float.pfm", b"PF\n1e300 2\n-1.0\n".to_vec(), "width \"1e300\""),
        ("nan.pfm", b"PF\n1 1\nNaN\n\0\0\0\0\0\0\0\0\0\0\0\0".to_vec(), "scale \"NaN\""),
        ("end.pfm", b"Pf\n1 1\n-1.0".to_vec(), "needs 4 bytes"),
    ] {
        let path = dir.join(name);
        std::fs::write(&path, bytes).unwrap();
        let err = read_pfm(&path).unwrap_err().to_string();
        assert!(err.contains(name) && err.contains(says), "{name}: {err}");
    }
    // A directory is not read as a file, nor called missing.
    let err = read_pfm(dir.path()).unwrap_err().to_string();
    assert!(err.contains("not a regular file"), "{err}");
    let err = write_pfm(dir.join("two.pfm"), &ramp(2, 2, 2, 0.0)).unwrap_err().to_string();
    assert!(err.contains("two.pfm") && err.contains("1 or 3 channels"), "{err}");
}
