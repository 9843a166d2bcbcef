//! The dataset generator's draws: cocog's SplitMix64 with the samplers the scene needs.
//! Datasets must be byte-identical across platforms and versions.

use cocog_formats::rng::SplitMix64;

#[derive(Clone, Debug)]
pub struct Rng(SplitMix64);

impl Rng {
    /// An independent stream for `tag`, so adding draws to one part of the scene does not
    /// shift every other part.
    pub fn fork(seed: u64, tag: u64) -> Self {
        let mut r = Self(SplitMix64::new(
            seed ^ tag.wrapping_mul(0xA24B_AED4_963E_E407),
        ));
        r.next_u64();
        r
    }

    pub fn next_u64(&mut self) -> u64 {
        self.0.next_u64()
    }

    /// Uniform in [0, 1) with 53 random bits.
    pub fn unit(&mut self) -> f64 {
        self.0.next_f64()
    }

    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.unit()
    }

    /// Approximately standard normal (sum of four uniforms, rescaled): bounded tails keep
    /// jittered Gaussians from landing far outside their object.
    pub fn normal(&mut self) -> f64 {
        let s: f64 = (0..4).map(|_| self.unit()).sum();
        (s - 2.0) * 3.0_f64.sqrt()
    }

    /// Uniform index in `0..n` (n > 0).
    pub fn below(&mut self, n: usize) -> usize {
        ((self.unit() * n as f64) as usize).min(n - 1)
    }

    /// Fisher–Yates shuffle.
    pub fn shuffle<T>(&mut self, v: &mut [T]) {
        for i in (1..v.len()).rev() {
            v.swap(i, self.below(i + 1));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn streams_are_deterministic_and_distinct() {
        let a: Vec<u64> = (0..4).map(|_| Rng::fork(7, 0).next_u64()).collect();
        assert!(a.windows(2).all(|w| w[0] == w[1]));
        let mut x = Rng::fork(7, 1);
        let mut y = Rng::fork(7, 2);
        assert_ne!(x.next_u64(), y.next_u64());
        let mut r = Rng::fork(3, 0);
        let mean = (0..20_000).map(|_| r.unit()).sum::<f64>() / 20_000.0;
        assert!((mean - 0.5).abs() < 0.01, "{mean}");
        let var = (0..20_000).map(|_| r.normal().powi(2)).sum::<f64>() / 20_000.0;
        assert!((var - 1.0).abs() < 0.05, "{var}");
    }
}
