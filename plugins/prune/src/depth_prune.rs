//! The depth-weighted pruning rule (the filter itself is `Splats::retain`).

use cocog_formats::splats::{Splats, sigmoid};

/// `true` for each Gaussian that survives: sigmoid(opacity) ≥ threshold / w(z).
pub fn keep_mask(s: &Splats, threshold: f64, range: f64) -> Vec<bool> {
    let z: Vec<f64> = s
        .means
        .iter()
        .skip(2)
        .step_by(3)
        .map(|v| f64::from(*v))
        .collect();
    let lo = z.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = z.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let span = hi - lo;
    z.iter()
        .zip(&s.opacities)
        .map(|(z, o)| {
            // All at one height (or a single Gaussian): every weight is 1.
            let w = if span > 0.0 {
                1.0 + (range - 1.0) * (z - lo) / span
            } else {
                1.0
            };
            f64::from(sigmoid(*o)) >= threshold / w
        })
        .collect()
}
