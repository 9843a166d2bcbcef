//! glTF 2.0 binary (`.glb`) with `KHR_gaussian_splatting` (Khronos Release Candidate, post
//! April-2026 semantics): linear scale, linear opacity, unit xyzw rotation, raw SH coefficients.
//!
//! Frame: glTF is +Y up. Like splat-transform (and so SuperSplat), we treat PLY space as glTF
//! space rotated 180° about Z, and apply that rotation to positions, rotations and SH on export;
//! import undoes it. The rotation is its own inverse. `asset.extras.cocog_frame` records it.

mod read;
mod write;

pub use read::read_glb;
pub use write::write_glb;

use crate::splats::{Splats, sh_rest_per_channel};

pub(crate) const EXTENSION: &str = "KHR_gaussian_splatting";
pub(crate) const FRAME_TAG: &str = "ply_rz180";

/// Rotates splats 180° about Z in place: p → (−x, −y, z), q → Rz(±180°)·q, and SH coefficient
/// (l, m) times (−1)^m. `inverse` picks −180°, so that the quaternion (not just the rotation)
/// comes back exactly after a forward and an inverse call.
pub(crate) fn rotate_z180(s: &mut Splats, inverse: bool) {
    let sign = if inverse { -1.0 } else { 1.0 };
    for p in s.means.chunks_exact_mut(3) {
        p[0] = -p[0];
        p[1] = -p[1];
    }
    for q in s.rotations.chunks_exact_mut(4) {
        let [w, x, y, z] = [q[0], q[1], q[2], q[3]];
        q.copy_from_slice(&[-z, -y, x, w].map(|v| sign * v));
    }
    let k = sh_rest_per_channel(s.sh_degree);
    if k == 0 {
        return;
    }
    for (j, v) in s.sh_rest.iter_mut().enumerate() {
        let coef = j % k;
        let l = ((coef + 1) as f64).sqrt().floor() as i64;
        let m = coef as i64 + 1 - l * l - l;
        if m.rem_euclid(2) == 1 {
            *v = -*v;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pose::rotation_from_wxyz;

    #[test]
    fn rz180_rotates_positions_and_rotations_consistently() {
        let mut s = Splats::with_capacity(1, 1);
        s.means.extend([1.0, 2.0, 3.0]);
        s.rotations.extend([0.9, 0.1, -0.3, 0.2]);
        s.log_scales.extend([0.0; 3]);
        s.opacities.push(0.0);
        s.sh_dc.extend([0.1, 0.2, 0.3]);
        s.sh_rest.extend((1..=9).map(|v| v as f32));
        let orig = s.clone();
        rotate_z180(&mut s, false);
        assert_eq!(&s.means, &[-1.0, -2.0, 3.0]);
        // R(q') must equal diag(−1, −1, 1)·R(q).
        let q = |v: &[f32]| [v[0] as f64, v[1] as f64, v[2] as f64, v[3] as f64];
        let r0 = rotation_from_wxyz(q(&orig.rotations));
        let r1 = rotation_from_wxyz(q(&s.rotations));
        let flip = glam::DMat3::from_diagonal(glam::DVec3::new(-1.0, -1.0, 1.0));
        assert!((flip * r0 - r1).abs_diff_eq(glam::DMat3::ZERO, 1e-6));
        // Degree 1 per channel: m = −1, 0, +1 → odd m flips.
        assert_eq!(&s.sh_rest[..3], &[-1.0, 2.0, -3.0]);
        rotate_z180(&mut s, true);
        assert_eq!(s, orig);
    }
}
