//! f64 reference of the per-Gaussian projection (EWA splatting, SH colour) and its backward.

use super::sh;
use super::{Gaussians64, Grads64};
use crate::types::{Camera, LOW_PASS, NEAR_PLANE, TILE_SIZE, sh_coeffs_per_channel};

type M3 = [[f64; 3]; 3];

/// Screen-space footprint of one Gaussian: what the rasterizer consumes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Projected {
    pub mean2d: [f64; 2],
    /// Inverse 2D covariance as (xx, xy, yy).
    pub conic: [f64; 3],
    pub depth: f64,
    pub opacity: f64,
    pub color: [f64; 3],
    /// Covered tiles, `[min, max)` per axis.
    pub tile_min: [u32; 2],
    pub tile_max: [u32; 2],
}

/// Gradient of a loss with respect to one `Projected` (the rasterizer backward's output).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ProjectedGrad {
    pub v_mean2d: [f64; 2],
    pub v_conic: [f64; 3],
    pub v_color: [f64; 3],
    pub v_opacity: f64,
    pub v_depth: f64,
}

/// Intermediates of the forward that the backward reuses.
struct Fwd {
    t: [f64; 3],
    w: M3,
    q: [f64; 4],
    qn: [f64; 4],
    rot: M3,
    s: [f64; 3],
    cov3: M3,
    jac: [[f64; 3]; 2],
    u_clamped: (f64, bool),
    v_clamped: (f64, bool),
    conic: [f64; 3],
    dir: [f64; 3],
    dist: f64,
    color_pre: [f64; 3],
    opacity: f64,
    out: Projected,
}

/// Rotation matrix of a unit (w, x, y, z) quaternion.
pub fn quat_to_rot(q: [f64; 4]) -> M3 {
    let [w, x, y, z] = q;
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

fn clamp_ratio(ratio: f64, lim_neg: f64, lim_pos: f64) -> (f64, bool) {
    if ratio < -lim_neg {
        (-lim_neg, true)
    } else if ratio > lim_pos {
        (lim_pos, true)
    } else {
        (ratio, false)
    }
}

fn forward(g: &Gaussians64, i: usize, cam: &Camera) -> Option<Fwd> {
    let (w, tcw) = cam.camera_from_world();
    let p = g.means[i];
    let t: [f64; 3] =
        std::array::from_fn(|r| w[r][0] * p[0] + w[r][1] * p[1] + w[r][2] * p[2] + tcw[r]);
    if !t.iter().all(|v| v.is_finite()) || t[2] < NEAR_PLANE {
        return None;
    }
    let q = g.quats[i];
    let qlen = q.iter().map(|v| v * v).sum::<f64>().sqrt();
    if !qlen.is_finite() || qlen <= 1e-12 {
        return None;
    }
    let qn = q.map(|v| v / qlen);
    let rot = quat_to_rot(qn);
    let s = g.log_scales[i].map(f64::exp);
    let cov3: M3 = std::array::from_fn(|r| {
        std::array::from_fn(|c| (0..3).map(|k| rot[r][k] * s[k] * s[k] * rot[c][k]).sum())
    });
    // Clamping the ray slope (as 3DGS/gsplat do) keeps the affine approximation sane for
    // Gaussians far outside the frustum.
    let (fw, fh) = (f64::from(cam.width), f64::from(cam.height));
    let u_clamped = clamp_ratio(
        t[0] / t[2],
        (cam.cx + 0.3 * fw) / cam.fx,
        (fw - cam.cx + 0.3 * fw) / cam.fx,
    );
    let v_clamped = clamp_ratio(
        t[1] / t[2],
        (cam.cy + 0.3 * fh) / cam.fy,
        (fh - cam.cy + 0.3 * fh) / cam.fy,
    );
    let jac = [
        [cam.fx / t[2], 0.0, -cam.fx * u_clamped.0 / t[2]],
        [0.0, cam.fy / t[2], -cam.fy * v_clamped.0 / t[2]],
    ];
    let jw: [[f64; 3]; 2] =
        std::array::from_fn(|r| std::array::from_fn(|c| (0..3).map(|k| jac[r][k] * w[k][c]).sum()));
    let quad = |a: usize, b: usize| -> f64 {
        (0..3)
            .map(|k| {
                (0..3)
                    .map(|l| jw[a][k] * cov3[k][l] * jw[b][l])
                    .sum::<f64>()
            })
            .sum()
    };
    let (ca, cb, cc) = (quad(0, 0) + LOW_PASS, quad(0, 1), quad(1, 1) + LOW_PASS);
    let det = ca * cc - cb * cb;
    if !det.is_finite() || det <= 0.0 {
        return None;
    }
    let conic = [cc / det, -cb / det, ca / det];
    let mean2d = [cam.fx * t[0] / t[2] + cam.cx, cam.fy * t[1] / t[2] + cam.cy];
    let mid = 0.5 * (ca + cc);
    let lambda = mid + (mid * mid - det).max(0.1).sqrt();
    let radius = (3.0 * lambda.sqrt()).ceil();
    let (tx, ty) = cam.tiles();
    let ts = f64::from(TILE_SIZE);
    let tile = |v: f64, hi: u32, up: bool| -> u32 {
        let f = if up {
            (v / ts).ceil()
        } else {
            (v / ts).floor()
        };
        f.clamp(0.0, f64::from(hi)) as u32
    };
    let tile_min = [
        tile(mean2d[0] - radius, tx, false),
        tile(mean2d[1] - radius, ty, false),
    ];
    let tile_max = [
        tile(mean2d[0] + radius, tx, true),
        tile(mean2d[1] + radius, ty, true),
    ];
    if tile_min[0] >= tile_max[0] || tile_min[1] >= tile_max[1] {
        return None;
    }

    let centre = cam.centre();
    let dv: [f64; 3] = std::array::from_fn(|k| p[k] - centre[k]);
    let dist = dv.iter().map(|v| v * v).sum::<f64>().sqrt();
    let dir = dv.map(|v| v / dist);
    let n = sh_coeffs_per_channel(g.sh_degree);
    let basis = sh::basis(dir, n);
    let coeffs = &g.sh[i * 3 * n..(i + 1) * 3 * n];
    let color_pre: [f64; 3] =
        std::array::from_fn(|c| 0.5 + (0..n).map(|k| coeffs[c * n + k] * basis[k]).sum::<f64>());
    let opacity = 1.0 / (1.0 + (-g.opacity_logits[i]).exp());
    let out = Projected {
        mean2d,
        conic,
        depth: t[2],
        opacity,
        color: color_pre.map(|c| c.max(0.0)),
        tile_min,
        tile_max,
    };
    // Checked before the colour clamp: max(-inf, 0) would hide a non-finite SH coefficient.
    let finite = out
        .mean2d
        .iter()
        .chain(&out.conic)
        .chain(&color_pre)
        .all(|v| v.is_finite())
        && opacity.is_finite();
    finite.then_some(Fwd {
        t,
        w,
        q,
        qn,
        rot,
        s,
        cov3,
        jac,
        u_clamped,
        v_clamped,
        conic,
        dir,
        dist,
        color_pre,
        opacity,
        out,
    })
}

/// Projects Gaussian `i`, or `None` when it is culled (behind the near plane, degenerate,
/// non-finite or off screen).
pub fn project(g: &Gaussians64, i: usize, cam: &Camera) -> Option<Projected> {
    forward(g, i, cam).map(|f| f.out)
}

/// Chains `v` back to the parameters of Gaussian `i`, adding into `grads`.
pub fn project_backward(
    g: &Gaussians64,
    i: usize,
    cam: &Camera,
    v: &ProjectedGrad,
    grads: &mut Grads64,
) {
    let Some(f) = forward(g, i, cam) else { return };
    let (fx, fy) = (cam.fx, cam.fy);
    let [x, y, z] = f.t;
    let mut v_t = [0.0; 3];
    v_t[0] += v.v_mean2d[0] * fx / z;
    v_t[1] += v.v_mean2d[1] * fy / z;
    v_t[2] += -v.v_mean2d[0] * fx * x / (z * z) - v.v_mean2d[1] * fy * y / (z * z) + v.v_depth;

    // conic = cov2⁻¹  ⇒  v_cov2 = -conic · V · conic, with V the symmetric matrix form of v_conic.
    let [a, b, c] = f.conic;
    let q2 = [[a, b], [b, c]];
    let vq = [
        [v.v_conic[0], 0.5 * v.v_conic[1]],
        [0.5 * v.v_conic[1], v.v_conic[2]],
    ];
    let v_cov2: [[f64; 2]; 2] = std::array::from_fn(|r| {
        std::array::from_fn(|cc| {
            -(0..2)
                .map(|k| (0..2).map(|l| q2[r][k] * vq[k][l] * q2[l][cc]).sum::<f64>())
                .sum::<f64>()
        })
    });
    let jw: [[f64; 3]; 2] = std::array::from_fn(|r| {
        std::array::from_fn(|cc| (0..3).map(|k| f.jac[r][k] * f.w[k][cc]).sum())
    });
    let v_cov3: M3 = std::array::from_fn(|r| {
        std::array::from_fn(|cc| {
            (0..2)
                .map(|k| {
                    (0..2)
                        .map(|l| jw[k][r] * v_cov2[k][l] * jw[l][cc])
                        .sum::<f64>()
                })
                .sum()
        })
    });
    let v_jw: [[f64; 3]; 2] = std::array::from_fn(|r| {
        std::array::from_fn(|cc| {
            2.0 * (0..2)
                .map(|k| {
                    (0..3)
                        .map(|l| v_cov2[r][k] * jw[k][l] * f.cov3[l][cc])
                        .sum::<f64>()
                })
                .sum::<f64>()
        })
    });
    let v_j: [[f64; 3]; 2] = std::array::from_fn(|r| {
        std::array::from_fn(|k| (0..3).map(|l| v_jw[r][l] * f.w[k][l]).sum())
    });
    let (uc, u_cl) = f.u_clamped;
    let (vc, v_cl) = f.v_clamped;
    v_t[2] += -fx / (z * z) * v_j[0][0] - fy / (z * z) * v_j[1][1];
    v_t[2] += v_j[0][2] * (fx * uc / (z * z) + if u_cl { 0.0 } else { fx * x / (z * z * z) });
    v_t[2] += v_j[1][2] * (fy * vc / (z * z) + if v_cl { 0.0 } else { fy * y / (z * z * z) });
    if !u_cl {
        v_t[0] += -fx / (z * z) * v_j[0][2];
    }
    if !v_cl {
        v_t[1] += -fy / (z * z) * v_j[1][2];
    }
    let mut v_p: [f64; 3] = std::array::from_fn(|k| (0..3).map(|r| f.w[r][k] * v_t[r]).sum());

    // cov3 = M Mᵀ with M = R diag(s).
    let m: M3 = std::array::from_fn(|r| std::array::from_fn(|cc| f.rot[r][cc] * f.s[cc]));
    let v_m: M3 = std::array::from_fn(|r| {
        std::array::from_fn(|cc| 2.0 * (0..3).map(|k| v_cov3[r][k] * m[k][cc]).sum::<f64>())
    });
    for j in 0..3 {
        let v_s: f64 = (0..3).map(|r| v_m[r][j] * f.rot[r][j]).sum();
        grads.v_log_scales[i][j] += v_s * f.s[j];
    }
    let vr: M3 = std::array::from_fn(|r| std::array::from_fn(|cc| v_m[r][cc] * f.s[cc]));
    let [w, qx, qy, qz] = f.qn;
    let v_qn = [
        2.0 * (-qz * vr[0][1] + qy * vr[0][2] + qz * vr[1][0] - qx * vr[1][2] - qy * vr[2][0]
            + qx * vr[2][1]),
        2.0 * (qy * vr[0][1] + qz * vr[0][2] + qy * vr[1][0] - 2.0 * qx * vr[1][1] - w * vr[1][2]
            + qz * vr[2][0]
            + w * vr[2][1]
            - 2.0 * qx * vr[2][2]),
        2.0 * (-2.0 * qy * vr[0][0] + qx * vr[0][1] + w * vr[0][2] + qx * vr[1][0] + qz * vr[1][2]
            - w * vr[2][0]
            + qz * vr[2][1]
            - 2.0 * qy * vr[2][2]),
        2.0 * (-2.0 * qz * vr[0][0] - w * vr[0][1] + qx * vr[0][2] + w * vr[1][0]
            - 2.0 * qz * vr[1][1]
            + qy * vr[1][2]
            + qx * vr[2][0]
            + qy * vr[2][1]),
    ];
    let qlen = f.q.iter().map(|v| v * v).sum::<f64>().sqrt();
    let dot: f64 = (0..4).map(|k| f.qn[k] * v_qn[k]).sum();
    for k in 0..4 {
        grads.v_quats[i][k] += (v_qn[k] - f.qn[k] * dot) / qlen;
    }

    let n = sh_coeffs_per_channel(g.sh_degree);
    let basis = sh::basis(f.dir, n);
    let dbasis = sh::basis_grad(f.dir, n);
    let coeffs = &g.sh[i * 3 * n..(i + 1) * 3 * n];
    let mut v_dir = [0.0; 3];
    for ch in 0..3 {
        let v_pre = if f.color_pre[ch] > 0.0 {
            v.v_color[ch]
        } else {
            0.0
        };
        for k in 0..n {
            grads.v_sh[i * 3 * n + ch * n + k] += v_pre * basis[k];
            for (axis, vd) in v_dir.iter_mut().enumerate() {
                *vd += v_pre * coeffs[ch * n + k] * dbasis[k][axis];
            }
        }
    }
    let dd: f64 = (0..3).map(|k| f.dir[k] * v_dir[k]).sum();
    for k in 0..3 {
        v_p[k] += (v_dir[k] - f.dir[k] * dd) / f.dist;
        grads.v_means[i][k] += v_p[k];
    }
    grads.v_opacity_logits[i] += v.v_opacity * f.opacity * (1.0 - f.opacity);
}
