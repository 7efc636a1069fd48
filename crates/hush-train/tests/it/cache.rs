use hush_train::{TrainError, decode_samples, encode_samples, round_trip};

use crate::synthetic;

const KEY: &str = "manifest 0123, features hdr,alb,nrm";

/// The cache gives the samples back rounded to f16 (relative error ≤ 2^-11 for normal values, absolute
/// ≤ 2^-25 below them), with their shapes.
#[test]
fn samples_come_back_as_f16() {
    let samples = synthetic(3);
    let bytes = encode_samples(KEY, &samples).unwrap();
    let back = decode_samples(&bytes, KEY).unwrap();
    assert_eq!(back.len(), 3);
    for (a, b) in samples.iter().zip(&back) {
        for (x, y) in [(&a.input, &b.input), (&a.target, &b.target)] {
            assert_eq!((x.width, x.height, x.channels), (y.width, y.height, y.channels));
            for (u, v) in x.data.iter().zip(&y.data) {
                assert!((u - v).abs() <= u.abs() / 2048.0 + 3e-8, "{u} came back as {v}");
            }
        }
    }
    // Round-tripping the returned samples changes nothing: a run trains on the same values whether its
    // cache was just built or read.
    let (again, again_bytes) = round_trip(KEY, &back).unwrap();
    assert_eq!(again, back);
    assert_eq!(again_bytes, bytes);
}

/// Bytes of another key, damaged, cut short or of something else are refused, each with its reason.
#[test]
fn a_stale_or_damaged_cache_is_refused() {
    let bytes = encode_samples(KEY, &synthetic(2)).unwrap();
    let reason = |b: &[u8], key: &str| match decode_samples(b, key) {
        Err(TrainError::Cache(why)) => why,
        other => panic!("expected a cache error, got {:?}", other.map(|s| s.len())),
    };
    assert!(reason(&bytes, "manifest 4567, features hdr,alb,nrm").contains("other data or settings"));
    // Only the parts that differ are named, and a long one is shortened.
    let samples = |n: usize| (0..n).map(|i| format!("view{i:03}@4spp")).collect::<Vec<_>>().join(" ");
    let (then, now) =
        (format!("preparation 1, samples {}", samples(200)), format!("preparation 2, samples {}", samples(200)));
    let bytes = encode_samples(&then, &synthetic(1)).unwrap();
    let why = reason(&bytes, &now);
    assert!(why.ends_with("other data or settings: preparation 1 then, preparation 2 now"), "{why}");
    let why = reason(&bytes, &format!("preparation 1, samples {}", samples(201)));
    assert!(why.contains("characters) then") && why.len() < 400, "{why}");
    let mut flipped = bytes.clone();
    flipped[bytes.len() / 2] ^= 0x10;
    assert!(reason(&flipped, KEY).contains("checksum"));
    assert!(reason(&bytes[..bytes.len() - 100], KEY).contains("checksum"));
    assert!(reason(b"{\"not\": \"a cache\"}", KEY).contains("not a hush sample cache"));
}

/// A value that f16 cannot hold is an error naming it, not an infinity in the cache.
#[test]
fn values_beyond_f16_are_refused() {
    let mut samples = synthetic(1);
    samples[0].input.data[5] = 1e6;
    let err = encode_samples(KEY, &samples).unwrap_err().to_string();
    assert!(err.contains("1000000") && err.contains("index 5"), "{err}");
}
