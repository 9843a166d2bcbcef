//! Rigid poses as the scene stores them: row-major 4×4 `[[f64; 4]; 4]`, OpenCV camera axes.

use glam::{DMat3, DQuat, DVec3};

/// Row-major 4×4 matrix.
pub type Mat4 = [[f64; 4]; 4];

/// Builds a row-major rigid transform from a rotation and a translation.
pub fn from_rt(r: DMat3, t: DVec3) -> Mat4 {
    let mut m = [[0.0; 4]; 4];
    for (i, row) in m.iter_mut().take(3).enumerate() {
        for (j, v) in row.iter_mut().take(3).enumerate() {
            *v = r.col(j)[i];
        }
        row[3] = t[i];
    }
    m[3][3] = 1.0;
    m
}

/// Splits a row-major rigid transform into rotation and translation.
pub fn to_rt(m: &Mat4) -> (DMat3, DVec3) {
    let col = |j: usize| DVec3::new(m[0][j], m[1][j], m[2][j]);
    (
        DMat3::from_cols(col(0), col(1), col(2)),
        DVec3::new(m[0][3], m[1][3], m[2][3]),
    )
}

/// Inverse of a rigid transform (rotation transposed, not a general inverse).
pub fn invert_rigid(m: &Mat4) -> Mat4 {
    let (r, t) = to_rt(m);
    let rt = r.transpose();
    from_rt(rt, -(rt * t))
}

/// Rotation matrix of a quaternion given w first, as COLMAP and INRIA store it; normalised first.
pub fn rotation_from_wxyz(q: [f64; 4]) -> DMat3 {
    DMat3::from_quat(DQuat::from_xyzw(q[1], q[2], q[3], q[0]).normalize())
}

/// Unit quaternion (w first, w ≥ 0) of a rotation matrix.
pub fn wxyz_from_rotation(r: DMat3) -> [f64; 4] {
    let q = DQuat::from_mat3(&r).normalize();
    let q = if q.w < 0.0 { -q } else { q };
    [q.w, q.x, q.y, q.z]
}

/// `world_from_camera` of a COLMAP image (`cam_from_world` as quaternion wxyz + translation).
pub fn world_from_colmap(qvec: [f64; 4], tvec: [f64; 3]) -> Mat4 {
    invert_rigid(&from_rt(rotation_from_wxyz(qvec), DVec3::from_array(tvec)))
}

/// COLMAP's `cam_from_world` (quaternion wxyz, translation) of a `world_from_camera` pose.
pub fn colmap_from_world(world_from_camera: &Mat4) -> ([f64; 4], [f64; 3]) {
    let (r, t) = to_rt(&invert_rigid(world_from_camera));
    (wxyz_from_rotation(r), t.to_array())
}

/// Flips camera axes y and z: OpenGL (x right, y up, looking down −z) ↔ OpenCV (x right, y down, z forward).
/// The flip is its own inverse.
pub fn flip_yz_camera_axes(world_from_camera: &Mat4) -> Mat4 {
    let mut m = *world_from_camera;
    for row in m.iter_mut().take(3) {
        row[1] = -row[1];
        row[2] = -row[2];
    }
    m
}

/// Whether every entry is finite and the 3×3 block is a rotation (orthonormal, det +1) within `tol`.
pub fn check_rigid(m: &Mat4, tol: f64) -> Result<(), String> {
    if m.iter().flatten().any(|v| !v.is_finite()) {
        return Err("contains NaN or infinity".to_owned());
    }
    let (r, _) = to_rt(m);
    let err = (r.transpose() * r - DMat3::IDENTITY)
        .to_cols_array()
        .iter()
        .fold(0.0_f64, |a, v| a.max(v.abs()));
    if err > tol {
        return Err(format!(
            "rotation is not orthonormal (max |RᵀR − I| = {err:.3e})"
        ));
    }
    if r.determinant() < 0.0 {
        return Err("rotation has determinant −1 (a reflection)".to_owned());
    }
    if m[3] != [0.0, 0.0, 0.0, 1.0] {
        return Err(format!("last row is {:?}, expected [0, 0, 0, 1]", m[3]));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Rotation from the textbook quaternion formula, written out independently of glam.
    fn textbook(q: [f64; 4]) -> [[f64; 3]; 3] {
        let n = q.iter().map(|v| v * v).sum::<f64>().sqrt();
        let [w, x, y, z] = q.map(|v| v / n);
        [
            [
                1.0 - 2.0 * (y * y + z * z),
                2.0 * (x * y - w * z),
                2.0 * (x * z + w * y),
            ],
            [
                2.0 * (x * y + w * z),
                1.0 - 2.0 * (x * x + z * z),
                2.0 * (y * z - w * x),
            ],
            [
                2.0 * (x * z - w * y),
                2.0 * (y * z + w * x),
                1.0 - 2.0 * (x * x + y * y),
            ],
        ]
    }

    #[test]
    fn quaternion_matches_textbook_and_round_trips() {
        let q = [0.3, -0.5, 0.2, 0.7];
        let r = rotation_from_wxyz(q);
        let t = textbook(q);
        for (i, row) in t.iter().enumerate() {
            for (j, v) in row.iter().enumerate() {
                assert!((r.col(j)[i] - v).abs() < 1e-12);
            }
        }
        let back = wxyz_from_rotation(r);
        let n = q.iter().map(|v| v * v).sum::<f64>().sqrt();
        for (a, b) in back.iter().zip(q) {
            assert!((a - b / n).abs() < 1e-12);
        }
    }

    #[test]
    fn inverse_composes_to_identity() {
        let m = world_from_colmap([0.9, 0.1, -0.3, 0.2], [1.0, -2.0, 0.5]);
        let (r, t) = to_rt(&m);
        let (ri, ti) = to_rt(&invert_rigid(&m));
        assert!(((ri * r) - DMat3::IDENTITY).abs_diff_eq(DMat3::ZERO, 1e-12));
        assert!((ri * t + ti).length() < 1e-12);
        assert!(check_rigid(&m, 1e-9).is_ok());
        let mut bad = m;
        bad[0][0] = f64::NAN;
        assert!(check_rigid(&bad, 1e-9).is_err());
    }
}
