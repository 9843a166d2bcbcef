//! The seeded generator every cocog stage and test draws from.
//!
//! Seeded outputs (densified points, synthetic datasets, split samples, view orders) must be
//! identical on every platform and version, which rand's `StdRng` does not promise, and a
//! training checkpoint must hold the generator, which here is one `u64`.

/// SplitMix64 (Steele, Lea & Flood 2014): one 64-bit state, full period.
#[derive(Clone, Debug)]
pub struct SplitMix64(u64);

impl SplitMix64 {
    /// A generator whose state is `state`: a seed, or what `state()` returned.
    pub fn new(state: u64) -> Self {
        Self(state)
    }

    /// The internal state; `SplitMix64::new(state)` continues the sequence from here.
    pub fn state(&self) -> u64 {
        self.0
    }

    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1) with 53 random bits.
    pub fn next_f64(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
}

#[cfg(test)]
mod tests {
    use super::SplitMix64;

    #[test]
    fn matches_the_published_sequence_and_resumes_from_its_state() {
        // Reference values of SplitMix64 seeded with 1234567 (Vigna's splitmix64.c).
        let mut r = SplitMix64::new(1_234_567);
        assert_eq!(r.next_u64(), 6_457_827_717_110_365_317);
        assert_eq!(r.next_u64(), 3_203_168_211_198_807_973);
        let mut copy = SplitMix64::new(r.state());
        assert_eq!(copy.next_u64(), r.next_u64());
        assert!((0..1000).all(|_| (0.0..1.0).contains(&r.next_f64())));
    }
}
