//! Real spherical harmonics in the INRIA 3DGS basis (m = -l..l, Condon–Shortley signs),
//! evaluated on a unit direction, plus their partial derivatives for the view-direction path.

const C0: f64 = 0.282_094_791_773_878_14;
const C1: f64 = 0.488_602_511_902_919_9;
const C2: [f64; 5] = [
    1.092_548_430_592_079,
    -1.092_548_430_592_079,
    0.315_391_565_252_520_05,
    -1.092_548_430_592_079,
    0.546_274_215_296_039_6,
];
const C3: [f64; 7] = [
    -0.590_043_589_926_643_5,
    2.890_611_442_640_554,
    -0.457_045_799_464_465_8,
    0.373_176_332_590_115_4,
    -0.457_045_799_464_465_8,
    1.445_305_721_320_277,
    -0.590_043_589_926_643_5,
];

/// Basis values for the first `n` (1, 4, 9 or 16) functions at unit direction `d`.
pub fn basis(d: [f64; 3], n: usize) -> [f64; 16] {
    let [x, y, z] = d;
    let (xx, yy, zz) = (x * x, y * y, z * z);
    let mut b = [0.0; 16];
    b[0] = C0;
    if n > 1 {
        b[1] = -C1 * y;
        b[2] = C1 * z;
        b[3] = -C1 * x;
    }
    if n > 4 {
        b[4] = C2[0] * x * y;
        b[5] = C2[1] * y * z;
        b[6] = C2[2] * (2.0 * zz - xx - yy);
        b[7] = C2[3] * x * z;
        b[8] = C2[4] * (xx - yy);
    }
    if n > 9 {
        b[9] = C3[0] * y * (3.0 * xx - yy);
        b[10] = C3[1] * x * y * z;
        b[11] = C3[2] * y * (4.0 * zz - xx - yy);
        b[12] = C3[3] * z * (2.0 * zz - 3.0 * xx - 3.0 * yy);
        b[13] = C3[4] * x * (4.0 * zz - xx - yy);
        b[14] = C3[5] * z * (xx - yy);
        b[15] = C3[6] * x * (xx - 3.0 * yy);
    }
    b
}

/// d basis_k / d(x, y, z), treating the direction components as independent (the
/// normalisation is differentiated separately by the caller).
pub fn basis_grad(d: [f64; 3], n: usize) -> [[f64; 3]; 16] {
    let [x, y, z] = d;
    let (xx, yy, zz) = (x * x, y * y, z * z);
    let mut g = [[0.0; 3]; 16];
    if n > 1 {
        g[1] = [0.0, -C1, 0.0];
        g[2] = [0.0, 0.0, C1];
        g[3] = [-C1, 0.0, 0.0];
    }
    if n > 4 {
        g[4] = [C2[0] * y, C2[0] * x, 0.0];
        g[5] = [0.0, C2[1] * z, C2[1] * y];
        g[6] = [-2.0 * C2[2] * x, -2.0 * C2[2] * y, 4.0 * C2[2] * z];
        g[7] = [C2[3] * z, 0.0, C2[3] * x];
        g[8] = [2.0 * C2[4] * x, -2.0 * C2[4] * y, 0.0];
    }
    if n > 9 {
        g[9] = [C3[0] * 6.0 * x * y, C3[0] * (3.0 * xx - 3.0 * yy), 0.0];
        g[10] = [C3[1] * y * z, C3[1] * x * z, C3[1] * x * y];
        g[11] = [
            C3[2] * -2.0 * x * y,
            C3[2] * (4.0 * zz - xx - 3.0 * yy),
            C3[2] * 8.0 * y * z,
        ];
        g[12] = [
            C3[3] * -6.0 * x * z,
            C3[3] * -6.0 * y * z,
            C3[3] * (6.0 * zz - 3.0 * xx - 3.0 * yy),
        ];
        g[13] = [
            C3[4] * (4.0 * zz - 3.0 * xx - yy),
            C3[4] * -2.0 * x * y,
            C3[4] * 8.0 * x * z,
        ];
        g[14] = [C3[5] * 2.0 * x * z, C3[5] * -2.0 * y * z, C3[5] * (xx - yy)];
        g[15] = [C3[6] * (3.0 * xx - 3.0 * yy), C3[6] * -6.0 * x * y, 0.0];
    }
    g
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn basis_grad_matches_finite_differences() {
        let d = [0.3, -0.5, 0.7];
        let g = basis_grad(d, 16);
        let eps = 1e-6;
        for axis in 0..3 {
            let (mut p, mut m) = (d, d);
            p[axis] += eps;
            m[axis] -= eps;
            let (bp, bm) = (basis(p, 16), basis(m, 16));
            for k in 0..16 {
                let fd = (bp[k] - bm[k]) / (2.0 * eps);
                assert!(
                    (fd - g[k][axis]).abs() < 1e-8,
                    "k={k} axis={axis}: {fd} vs {}",
                    g[k][axis]
                );
            }
        }
    }

    #[test]
    fn dc_and_degree_one_signs_follow_inria() {
        let b = basis([1.0, 0.0, 0.0], 4);
        assert_eq!(b[0], C0);
        // INRIA: -C1*y*sh1 + C1*z*sh2 - C1*x*sh3.
        assert_eq!(b[3], -C1);
        assert_eq!(basis([0.0, 1.0, 0.0], 4)[1], -C1);
        assert_eq!(basis([0.0, 0.0, 1.0], 4)[2], C1);
    }
}
