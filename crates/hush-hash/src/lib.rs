//! Seeded random streams and content fingerprints shared by hush's crates: [`SplitMix64`] (procedural
//! scenes, generated views and render seeds, initial weights, training crops) and [`fnv1a`] (weight names,
//! sample-cache keys). No dependencies, the same numbers on every platform: the determinism tests of the
//! crates that use them hold these constants in place.
//!
//! ```
//! use hush_hash::{SplitMix64, fnv1a};
//!
//! let mut a = SplitMix64(7);
//! let mut b = SplitMix64(7);
//! assert_eq!(a.next_u64(), b.next_u64());
//! let x = a.next_f64();
//! assert!((0.0..1.0).contains(&x));
//! assert!(SplitMix64::keyed(3, 9).below(10) < 10);
//! assert_eq!(fnv1a(b""), 0xcbf2_9ce4_8422_2325);
//! assert_eq!(fnv1a(b"a"), 0xaf63_dc4c_8601_ec8c);
//! ```

/// Steele, Lea and Flood's SplitMix64: a 64-bit state advanced by the golden-ratio increment and mixed by
/// two multiply-xorshift rounds. Tiny and seedable; its state is one number.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SplitMix64(pub u64);

impl SplitMix64 {
    /// The increment: 2^64 divided by the golden ratio.
    pub const GOLDEN: u64 = 0x9e37_79b9_7f4a_7c15;

    /// A stream keyed by `(seed, stream)`: the seed is mixed once, then offset by the stream times
    /// [`Self::GOLDEN`], so that neighbouring streams of one seed are unrelated.
    pub fn keyed(seed: u64, stream: u64) -> Self {
        let a = SplitMix64(seed ^ 0x5851_f42d_4c95_7f2d).next_u64();
        SplitMix64(a ^ stream.wrapping_mul(Self::GOLDEN))
    }

    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(Self::GOLDEN);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1), a multiple of 2^-53.
    pub fn next_f64(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Uniform in [0, 1), a multiple of 2^-24 (exact in f32).
    pub fn next_f32(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 / (1u64 << 24) as f32
    }

    /// Uniform in [lo, hi), from [`Self::next_f32`].
    pub fn uniform(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.next_f32()
    }

    /// Uniform in `0..n` (n > 0) by Lemire's multiply-shift: a bias below n / 2^64.
    pub fn below(&mut self, n: u64) -> u64 {
        ((self.next_u64() as u128 * n as u128) >> 64) as u64
    }
}

/// The 64-bit FNV-1a hash of `bytes`: a stable, dependency-free fingerprint (of weight names, cache keys).
pub fn fnv1a(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325, |h, &b| (h ^ b as u64).wrapping_mul(0x0100_0000_01b3))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The first outputs of SplitMix64 seeded with 1234567 (computed independently from Vigna's `splitmix64.c`);
    /// every seeded stream of hush depends on them.
    #[test]
    fn splitmix64_matches_the_reference() {
        let mut r = SplitMix64(1_234_567);
        let got: Vec<u64> = (0..3).map(|_| r.next_u64()).collect();
        assert_eq!(got, [6_457_827_717_110_365_317, 3_203_168_211_198_807_973, 9_817_491_932_198_370_423]);
    }

    /// FNV-1a's published test vectors.
    #[test]
    fn fnv1a_matches_the_published_vectors() {
        assert_eq!(fnv1a(b"foobar"), 0x85944171f73967e8);
        assert_eq!(fnv1a(b"a"), 0xaf63dc4c8601ec8c);
    }
}
