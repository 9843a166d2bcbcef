//! The pruning rule and an in-place filter over the structure-of-arrays splats.

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

/// Keeps the Gaussians whose `keep` entry is true, in order.
pub fn retain(s: &mut Splats, keep: &[bool]) {
    fn filter(v: &mut Vec<f32>, width: usize, keep: &[bool]) {
        let mut out = 0;
        for (i, k) in keep.iter().enumerate() {
            if *k {
                v.copy_within(i * width..(i + 1) * width, out * width);
                out += 1;
            }
        }
        v.truncate(out * width);
    }
    let k3 = 3 * s.rest_per_channel();
    filter(&mut s.means, 3, keep);
    filter(&mut s.log_scales, 3, keep);
    filter(&mut s.rotations, 4, keep);
    filter(&mut s.opacities, 1, keep);
    filter(&mut s.sh_dc, 3, keep);
    if k3 > 0 {
        filter(&mut s.sh_rest, k3, keep);
    }
}
