//! f64 reference of the training image loss (1 − λ)·L1 + λ·(1 − SSIM) and its gradient.
//! SSIM is the 3DGS one: 11×11 Gaussian window (σ = 1.5), zero padding, C1 = 0.01²,
//! C2 = 0.03², averaged over pixels and channels of each image and then over images.

pub const WINDOW: usize = 11;
pub const SIGMA: f64 = 1.5;
pub const C1: f64 = 0.01 * 0.01;
pub const C2: f64 = 0.03 * 0.03;

/// Normalised 1D Gaussian taps; the 2D window is their outer product.
pub fn window() -> [f64; WINDOW] {
    let half = (WINDOW / 2) as f64;
    let mut w: [f64; WINDOW] =
        std::array::from_fn(|i| (-((i as f64 - half).powi(2)) / (2.0 * SIGMA * SIGMA)).exp());
    let sum: f64 = w.iter().sum();
    w.iter_mut().for_each(|v| *v /= sum);
    w
}

/// Zero-padded 2D Gaussian filter of one channel plane.
fn blur(plane: &[f64], width: usize, height: usize) -> Vec<f64> {
    let w = window();
    let r = (WINDOW / 2) as isize;
    let mut out = vec![0.0; plane.len()];
    for y in 0..height as isize {
        for x in 0..width as isize {
            let mut acc = 0.0;
            for (j, wy) in w.iter().enumerate() {
                let sy = y + j as isize - r;
                if sy < 0 || sy >= height as isize {
                    continue;
                }
                for (i, wx) in w.iter().enumerate() {
                    let sx = x + i as isize - r;
                    if sx >= 0 && sx < width as isize {
                        acc += wy * wx * plane[(sy as usize) * width + sx as usize];
                    }
                }
            }
            out[(y as usize) * width + x as usize] = acc;
        }
    }
    out
}

/// Loss of one image pair (row-major rgb) and its gradient with respect to `pred`.
pub fn image_loss(
    pred: &[[f64; 3]],
    target: &[[f64; 3]],
    width: usize,
    height: usize,
    lambda: f64,
) -> (f64, Vec<[f64; 3]>) {
    let n = (width * height * 3) as f64;
    let mut grad = vec![[0.0; 3]; pred.len()];
    let mut l1 = 0.0;
    let mut ssim = 0.0;
    for c in 0..3 {
        let x: Vec<f64> = pred.iter().map(|p| p[c]).collect();
        let y: Vec<f64> = target.iter().map(|p| p[c]).collect();
        let prod =
            |a: &[f64], b: &[f64]| -> Vec<f64> { a.iter().zip(b).map(|(a, b)| a * b).collect() };
        let (mx, my) = (blur(&x, width, height), blur(&y, width, height));
        let sxx = blur(&prod(&x, &x), width, height);
        let syy = blur(&prod(&y, &y), width, height);
        let sxy = blur(&prod(&x, &y), width, height);
        let (mut a, mut b, mut cc) = (vec![0.0; x.len()], vec![0.0; x.len()], vec![0.0; x.len()]);
        for p in 0..x.len() {
            let (vx, vy, cxy) = (
                sxx[p] - mx[p] * mx[p],
                syy[p] - my[p] * my[p],
                sxy[p] - mx[p] * my[p],
            );
            let (n1, n2) = (2.0 * mx[p] * my[p] + C1, 2.0 * cxy + C2);
            let (d1, d2) = (mx[p] * mx[p] + my[p] * my[p] + C1, vx + vy + C2);
            let s = n1 * n2 / (d1 * d2);
            ssim += s;
            // Partials of s in (μx, σx², σxy), then re-expressed in (μx, E[x²], E[xy]).
            let s_mu = 2.0 * my[p] * n2 / (d1 * d2) - s * 2.0 * mx[p] / d1;
            let s_var = -s / d2;
            let s_cov = 2.0 * n1 / (d1 * d2);
            a[p] = s_mu - 2.0 * mx[p] * s_var - my[p] * s_cov;
            b[p] = s_var;
            cc[p] = s_cov;
            l1 += (x[p] - y[p]).abs();
        }
        // The window is symmetric, so the adjoint of the zero-padded blur is the blur itself.
        let (ga, gb, gc) = (
            blur(&a, width, height),
            blur(&b, width, height),
            blur(&cc, width, height),
        );
        for p in 0..x.len() {
            let d_ssim = ga[p] + 2.0 * x[p] * gb[p] + y[p] * gc[p];
            let sign = (x[p] - y[p]).signum() * f64::from(u8::from(x[p] != y[p]));
            grad[p][c] = ((1.0 - lambda) * sign - lambda * d_ssim) / n;
        }
    }
    let loss = (1.0 - lambda) * l1 / n + lambda * (1.0 - ssim / n);
    (loss, grad)
}
