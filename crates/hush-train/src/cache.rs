//! Prepared samples as bytes, for an on-disk cache: every value of each sample's input and target as f16.
//!
//! Preparing a sample reads its EXR files and applies the exposure and transfer function
//! ([`TrainSample::from_linear`]); the cache keeps the result at half the size of f32. The bytes carry a
//! caller's key (what the samples were made from: dataset, features, transfer, ...) and a checksum, and
//! [`decode_samples`] refuses bytes of another key, truncated or altered bytes, so a stale or damaged cache
//! is rebuilt, never trusted.
//!
//! Layout (little-endian): the magic `HUSHF16\n`, the format version (u32), the key (u32 length + UTF-8),
//! the number of samples (u32), per sample width, height, input channels and target channels (u32 each),
//! then per sample its input and its target values (interleaved as [`Image`], f16), and last the FNV-1a
//! 64-bit hash of everything before it.

use half::f16;
use hush_dataset::Image;
use hush_hash::fnv1a;

use crate::{Result, TrainError, TrainSample};

const MAGIC: &[u8; 8] = b"HUSHF16\n";
const VERSION: u32 = 1;

/// The samples as cache bytes under `key`. Fails if a value is not finite or does not fit f16 (|v| > 65504):
/// prepared samples are in the transfer function's range, so such a value means the samples are not.
pub fn encode_samples(key: &str, samples: &[TrainSample]) -> Result<Vec<u8>> {
    let values: usize = samples.iter().map(|s| s.input.data.len() + s.target.data.len()).sum();
    let mut out = Vec::with_capacity(64 + key.len() + 16 * samples.len() + 2 * values);
    out.extend_from_slice(MAGIC);
    put_u32(&mut out, VERSION);
    put_u32(&mut out, len_u32(key.len())?);
    out.extend_from_slice(key.as_bytes());
    put_u32(&mut out, len_u32(samples.len())?);
    for s in samples {
        for v in [s.input.width, s.input.height, s.input.channels, s.target.channels] {
            put_u32(&mut out, len_u32(v)?);
        }
    }
    for (i, s) in samples.iter().enumerate() {
        for (what, im) in [("input", &s.input), ("target", &s.target)] {
            for (k, &v) in im.data.iter().enumerate() {
                let h = f16::from_f32(v);
                if !h.is_finite() {
                    return Err(TrainError::Data(format!(
                        "sample {i} {what} value {v} at index {k} does not fit f16; prepared samples should lie in \
                         the transfer function's range"
                    )));
                }
                out.extend_from_slice(&h.to_le_bytes());
            }
        }
    }
    let hash = fnv1a(&out);
    out.extend_from_slice(&hash.to_le_bytes());
    Ok(out)
}

/// What differs between the key a cache was written under and the key now, part by part (keys are
/// `, `-separated parts, such as the dataset's views, the preparation version, the features and the list of
/// samples); a long part is shortened, since a list of hundreds of samples would bury the difference.
fn key_difference(stored: &str, now: &str) -> String {
    let shorten = |s: &str| {
        let count = s.chars().count();
        if count <= 120 {
            s.to_string()
        } else {
            format!("{}… ({count} characters)", s.chars().take(100).collect::<String>())
        }
    };
    let (then, now_parts): (Vec<&str>, Vec<&str>) = (stored.split(", ").collect(), now.split(", ").collect());
    if then.len() != now_parts.len() {
        return format!("{} then, {} now", shorten(stored), shorten(now));
    }
    let parts: Vec<String> = then
        .iter()
        .zip(&now_parts)
        .filter(|(a, b)| a != b)
        .map(|(a, b)| format!("{} then, {} now", shorten(a), shorten(b)))
        .collect();
    parts.join("; ")
}

/// The samples stored in `bytes`, if they are intact cache bytes written under `key`; otherwise a
/// [`TrainError::Cache`] saying why (another key, another format, truncated, checksum mismatch).
pub fn decode_samples(bytes: &[u8], key: &str) -> Result<Vec<TrainSample>> {
    let bad = |why: String| TrainError::Cache(why);
    if bytes.len() < MAGIC.len() + 8 || &bytes[..MAGIC.len()] != MAGIC {
        return Err(bad("not a hush sample cache".into()));
    }
    let (body, tail) = bytes.split_at(bytes.len() - 8);
    let stored = u64::from_le_bytes(tail.try_into().expect("8 bytes"));
    if fnv1a(body) != stored {
        return Err(bad("its checksum does not match: the file is damaged or was cut short".into()));
    }
    let mut r = Reader { bytes: body, at: MAGIC.len() };
    let version = r.u32()?;
    if version != VERSION {
        return Err(bad(format!("format version {version}, this hush reads {VERSION}")));
    }
    let key_len = r.u32()? as usize;
    let stored_key = std::str::from_utf8(r.take(key_len)?).map_err(|_| bad("its key is not UTF-8".into()))?;
    if stored_key != key {
        return Err(bad(format!("made from other data or settings: {}", key_difference(stored_key, key))));
    }
    let count = r.u32()? as usize;
    let mut shapes = Vec::with_capacity(count.min(1 << 16));
    for _ in 0..count {
        shapes.push([r.u32()? as usize, r.u32()? as usize, r.u32()? as usize, r.u32()? as usize]);
    }
    let mut samples = Vec::with_capacity(shapes.len());
    for [width, height, in_channels, target_channels] in shapes {
        let mut image = |channels: usize| -> Result<Image> {
            let n = width
                .checked_mul(height)
                .and_then(|p| p.checked_mul(channels))
                .ok_or_else(|| bad("size overflows".into()))?;
            let raw = r.take(n.checked_mul(2).ok_or_else(|| bad("size overflows".into()))?)?;
            let data = raw.chunks_exact(2).map(|b| f16::from_le_bytes([b[0], b[1]]).to_f32()).collect();
            Ok(Image { width, height, channels, data })
        };
        let input = image(in_channels)?;
        let target = image(target_channels)?;
        samples.push(TrainSample { input, target });
    }
    if r.at != body.len() {
        return Err(bad(format!("{} bytes after the last sample", body.len() - r.at)));
    }
    Ok(samples)
}

/// The samples as they come back from the cache: each value rounded to f16. Training on these whether the
/// cache was just built or read keeps a run's data the same either way.
pub fn round_trip(key: &str, samples: &[TrainSample]) -> Result<(Vec<TrainSample>, Vec<u8>)> {
    let bytes = encode_samples(key, samples)?;
    Ok((decode_samples(&bytes, key)?, bytes))
}

struct Reader<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl Reader<'_> {
    fn take(&mut self, n: usize) -> Result<&[u8]> {
        let end = self.at.checked_add(n).filter(|&e| e <= self.bytes.len());
        let end = end.ok_or_else(|| TrainError::Cache("it ends early".into()))?;
        let out = &self.bytes[self.at..end];
        self.at = end;
        Ok(out)
    }

    fn u32(&mut self) -> Result<u32> {
        Ok(u32::from_le_bytes(self.take(4)?.try_into().expect("4 bytes")))
    }
}

fn put_u32(out: &mut Vec<u8>, v: u32) {
    out.extend_from_slice(&v.to_le_bytes());
}

fn len_u32(n: usize) -> Result<u32> {
    u32::try_from(n).map_err(|_| TrainError::Data(format!("{n} is too large for the sample cache")))
}
