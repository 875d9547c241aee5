//! SplitMix64 (Steele, Lea & Flood 2014, "Fast splittable pseudorandom number generators",
//! OOPSLA): a small, fast generator with a 64-bit state, the same on every platform. The Monte
//! Carlo reference draws one stream per texel from it; the generated scenes and the tests draw
//! their inputs from it.

/// The increment of the state per draw: 2^64 divided by the golden ratio, odd.
pub(crate) const GAMMA: u64 = 0x9E37_79B9_7F4A_7C15;

/// A SplitMix64 stream; the tuple field is its state (the seed, before the first draw).
#[derive(Clone, Debug)]
pub struct SplitMix64(pub u64);

impl SplitMix64 {
    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(GAMMA);
        mix64(self.0)
    }

    /// Uniform in \[0, 1), 53 bits.
    pub fn next_f64(&mut self) -> f64 {
        unit_f64(self.next_u64())
    }

    /// Uniform in \[lo, hi).
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.next_f64()
    }
}

/// SplitMix64's finaliser (Stafford's "Mix13" variant of MurmurHash3's): a bijection of 64-bit
/// words in which each input bit changes each output bit with probability about 1/2; also a
/// hash for seeding one stream per item.
pub(crate) fn mix64(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// The top 53 bits of `bits` as a value uniform in \[0, 1).
pub(crate) fn unit_f64(bits: u64) -> f64 {
    (bits >> 11) as f64 / (1u64 << 53) as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The first outputs for seed 1234567, from the reference implementation
    /// (`splitmix64.c`, Vigna).
    #[test]
    fn matches_the_reference_stream() {
        let mut r = SplitMix64(1234567);
        let first: Vec<u64> = (0..3).map(|_| r.next_u64()).collect();
        assert_eq!(
            first,
            [
                6457827717110365317,
                3203168211198807973,
                9817491932198370423
            ]
        );
    }
}
