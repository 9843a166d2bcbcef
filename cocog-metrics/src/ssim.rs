//! PSNR and the two SSIM conventions, bit-for-bit the formulas of scikit-image's
//! `peak_signal_noise_ratio` / `structural_similarity` in f64.
//!
//! scikit-image filters the whole image (reflect padding) and then crops `(win−1)/2` pixels from
//! every border before averaging. The crop equals the filter radius, so every kept value only sees
//! pixels inside the image: filtering over the "valid" region alone gives the same numbers without
//! any padding.

use crate::FloatImage;

/// Which SSIM convention to compute.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SsimConvention {
    /// Deblur-NeRF's `metrics.py`: images mapped to [−1,1], data range 2, 7×7 uniform window,
    /// sample covariance (N/(N−1)), crop 3. What the deblurring papers' tables report.
    DeblurNerf,
    /// Wang et al. 2004: images on [0,1], data range 1, 11×11 Gaussian window (σ = 1.5, truncated
    /// at 3.5σ), population covariance, crop 5.
    Gaussian11,
}

const K1: f64 = 0.01;
const K2: f64 = 0.03;

impl SsimConvention {
    /// Separable 1-D window weights (sum to 1).
    fn window(self) -> Vec<f64> {
        match self {
            Self::DeblurNerf => vec![1.0 / 7.0; 7],
            Self::Gaussian11 => {
                let sigma: f64 = 1.5;
                // scipy.ndimage's radius rule: int(truncate·σ + 0.5) with truncate = 3.5.
                let radius = (3.5 * sigma + 0.5) as i32;
                let w: Vec<f64> = (-radius..=radius)
                    .map(|x| (-0.5 * f64::from(x * x) / (sigma * sigma)).exp())
                    .collect();
                let sum: f64 = w.iter().sum();
                w.into_iter().map(|v| v / sum).collect()
            }
        }
    }

    /// Maps a [0,1] value into the convention's input range.
    fn map(self, v: f64) -> f64 {
        match self {
            Self::DeblurNerf => 2.0 * v - 1.0,
            Self::Gaussian11 => v,
        }
    }

    fn data_range(self) -> f64 {
        match self {
            Self::DeblurNerf => 2.0,
            Self::Gaussian11 => 1.0,
        }
    }

    fn cov_norm(self, win: usize) -> f64 {
        match self {
            Self::DeblurNerf => {
                let np = (win * win) as f64;
                np / (np - 1.0)
            }
            Self::Gaussian11 => 1.0,
        }
    }

    /// The smallest image side the window fits in.
    pub fn min_side(self) -> u32 {
        self.window().len() as u32
    }
}

/// PSNR in dB on [0,1]: `10·log10(1/MSE)` over all pixels and channels. Identical images give
/// `+inf`. Both images must have the same size (checked by the caller that knows the file names).
pub fn psnr(a: &FloatImage, b: &FloatImage) -> f64 {
    assert_eq!(a.data.len(), b.data.len(), "psnr: size mismatch");
    let sse: f64 = a
        .data
        .iter()
        .zip(&b.data)
        .map(|(x, y)| (x - y) * (x - y))
        .sum();
    let mse = sse / a.data.len() as f64;
    10.0 * (1.0 / mse).log10()
}

/// Mean SSIM over the three channels. Returns `None` when a side is smaller than the window
/// (scikit-image raises there).
pub fn ssim(a: &FloatImage, b: &FloatImage, conv: SsimConvention) -> Option<f64> {
    assert_eq!(
        (a.width, a.height),
        (b.width, b.height),
        "ssim: size mismatch"
    );
    let w = conv.window();
    let win = w.len();
    let (width, height) = (a.width as usize, a.height as usize);
    if width < win || height < win {
        return None;
    }
    let c1 = (K1 * conv.data_range()).powi(2);
    let c2 = (K2 * conv.data_range()).powi(2);
    let cov_norm = conv.cov_norm(win);
    let mut total = 0.0;
    for c in 0..3 {
        let x = a.plane(c, |v| conv.map(v));
        let y = b.plane(c, |v| conv.map(v));
        let stats = filtered_moments(&x, &y, width, height, &w);
        let mut sum = 0.0;
        for m in &stats {
            let [ux, uy, uxx, uyy, uxy] = *m;
            let vx = cov_norm * (uxx - ux * ux);
            let vy = cov_norm * (uyy - uy * uy);
            let vxy = cov_norm * (uxy - ux * uy);
            let a1 = 2.0 * ux * uy + c1;
            let a2 = 2.0 * vxy + c2;
            let b1 = ux * ux + uy * uy + c1;
            let b2 = vx + vy + c2;
            sum += (a1 * a2) / (b1 * b2);
        }
        total += sum / stats.len() as f64;
    }
    Some(total / 3.0)
}

/// Window-weighted means of x, y, x², y², xy over every position where the window fits entirely,
/// row-major over the (height−win+1)×(width−win+1) valid region.
fn filtered_moments(x: &[f64], y: &[f64], width: usize, height: usize, w: &[f64]) -> Vec<[f64; 5]> {
    let win = w.len();
    let ow = width - win + 1;
    let oh = height - win + 1;
    // Horizontal pass over every row, then vertical over the result: separable, O(win) per pixel.
    let mut horiz = vec![[0.0f64; 5]; height * ow];
    for row in 0..height {
        let base = row * width;
        for ox in 0..ow {
            let mut acc = [0.0; 5];
            for (k, &wk) in w.iter().enumerate() {
                let (xv, yv) = (x[base + ox + k], y[base + ox + k]);
                acc[0] += wk * xv;
                acc[1] += wk * yv;
                acc[2] += wk * xv * xv;
                acc[3] += wk * yv * yv;
                acc[4] += wk * xv * yv;
            }
            horiz[row * ow + ox] = acc;
        }
    }
    let mut out = vec![[0.0f64; 5]; oh * ow];
    for oy in 0..oh {
        for (k, &wk) in w.iter().enumerate() {
            let src = &horiz[(oy + k) * ow..(oy + k + 1) * ow];
            let dst = &mut out[oy * ow..(oy + 1) * ow];
            for (d, s) in dst.iter_mut().zip(src) {
                for i in 0..5 {
                    d[i] += wk * s[i];
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn image(width: u32, height: u32, f: impl Fn(u32, u32, u32) -> u8) -> FloatImage {
        let mut rgb = Vec::new();
        for y in 0..height {
            for x in 0..width {
                for c in 0..3 {
                    rgb.push(f(x, y, c));
                }
            }
        }
        FloatImage::from_rgb8(width, height, &rgb)
    }

    #[test]
    fn identical_images_score_perfectly() {
        let a = image(20, 15, |x, y, c| (x * 11 + y * 5 + c * 70) as u8);
        assert_eq!(psnr(&a, &a), f64::INFINITY);
        for conv in [SsimConvention::DeblurNerf, SsimConvention::Gaussian11] {
            let s = ssim(&a, &a, conv).unwrap();
            assert!((s - 1.0).abs() < 1e-12, "{conv:?}: {s}");
        }
    }

    #[test]
    fn psnr_of_a_constant_offset() {
        // Every sample off by 51/255 = 0.2 → MSE 0.04 → 13.979 dB.
        let a = image(4, 4, |_, _, _| 100);
        let b = image(4, 4, |_, _, _| 151);
        assert!((psnr(&a, &b) - 10.0 * (1.0f64 / 0.04).log10()).abs() < 1e-12);
    }

    #[test]
    fn gaussian_window_matches_scipy_radius_rule() {
        let w = SsimConvention::Gaussian11.window();
        assert_eq!(w.len(), 11);
        assert!((w.iter().sum::<f64>() - 1.0).abs() < 1e-15);
        assert!(w[5] > w[4] && (w[4] - w[6]).abs() < 1e-18);
    }

    #[test]
    fn too_small_for_the_window_is_none() {
        let a = image(10, 6, |_, _, _| 0);
        assert!(ssim(&a, &a, SsimConvention::DeblurNerf).is_none());
        let a = image(10, 10, |_, _, _| 0);
        assert!(ssim(&a, &a, SsimConvention::DeblurNerf).is_some());
        assert!(ssim(&a, &a, SsimConvention::Gaussian11).is_none());
    }

    #[test]
    fn constant_images_reduce_to_the_luminance_term() {
        // With no structure, SSIM = (2·μx·μy + C1)/(μx² + μy² + C1): a closed form to check against.
        let a = image(12, 12, |_, _, _| 51);
        let b = image(12, 12, |_, _, _| 204);
        let (mx, my) = (0.2f64, 0.8f64);
        let c1 = (K1 * 1.0f64).powi(2);
        let want = (2.0 * mx * my + c1) / (mx * mx + my * my + c1);
        let got = ssim(&a, &b, SsimConvention::Gaussian11).unwrap();
        assert!((got - want).abs() < 1e-12, "{got} vs {want}");
    }
}
