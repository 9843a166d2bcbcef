//! Gaussians from a point cloud and the scene extent, both by the INRIA 3DGS rules.

use std::num::NonZero;

use cocog_engine::{Camera, GaussianParams};
use kiddo::{ImmutableKdTree, SquaredEuclidean};

use crate::TrainError;

/// The degree-0 real SH basis constant, 1 / (2√π).
pub const SH_C0: f32 = 0.282_094_8;
/// INRIA clamps the squared neighbour distance so duplicated points still get a finite scale.
const MIN_DIST2: f64 = 1e-7;
/// Opacity of a fresh Gaussian.
const INIT_OPACITY: f32 = 0.1;

/// Colour in [0, 1] to the SH DC coefficient that reproduces it (INRIA `RGB2SH`).
pub fn rgb_to_sh(c: f32) -> f32 {
    (c - 0.5) / SH_C0
}

pub fn inverse_sigmoid(p: f32) -> f32 {
    (p / (1.0 - p)).ln()
}

/// One Gaussian per point at SH degree 0: log-scale (isotropic) of the root mean squared
/// distance to the 3 nearest other points (INRIA `distCUDA2`), identity rotation, opacity 0.1
/// and the DC term from `colors` (linear [0, 1] RGB). Higher SH degrees are added by the
/// trainer as they become active, so a degree-0 start wastes no memory.
pub fn init_from_points(
    positions: &[[f32; 3]],
    colors: &[[f32; 3]],
) -> Result<GaussianParams, TrainError> {
    if positions.len() != colors.len() {
        return Err(TrainError::Invalid(format!(
            "{} points but {} colours",
            positions.len(),
            colors.len()
        )));
    }
    if positions.len() < 2 {
        return Err(TrainError::Invalid(
            "need at least two points to size Gaussians from their neighbours".into(),
        ));
    }
    if positions.iter().flatten().any(|v| !v.is_finite()) {
        return Err(TrainError::Invalid("non-finite point position".into()));
    }
    let pts: Vec<[f64; 3]> = positions.iter().map(|p| p.map(f64::from)).collect();
    let mut g = GaussianParams::default();
    for ((p, c), log_scale) in pts.iter().zip(colors).zip(neighbour_log_scales(&pts)) {
        g.means.push(p.map(|v| v as f32));
        g.log_scales.push([log_scale; 3]);
        g.quats.push([1.0, 0.0, 0.0, 0.0]);
        g.opacity_logits.push(inverse_sigmoid(INIT_OPACITY));
        g.sh.extend(c.map(rgb_to_sh));
    }
    Ok(g)
}

/// The isotropic log-scale INRIA gives a fresh Gaussian at each of `pts` (at least two): the
/// log of the root mean squared distance to its 3 nearest other points (`distCUDA2`).
pub fn neighbour_log_scales(pts: &[[f64; 3]]) -> Vec<f32> {
    let tree: ImmutableKdTree<f64, 3> = ImmutableKdTree::new_from_slice(pts);
    // The query point itself comes back first, so ask for one more than the 3 neighbours.
    let k = NonZero::new(4.min(pts.len()).max(1)).expect("at least one");
    pts.iter()
        .map(|p| {
            let near = tree.nearest_n::<SquaredEuclidean>(p, k);
            // Drop exactly one entry for the point itself (duplicates of it still count).
            let dists: Vec<f64> = near.iter().skip(1).map(|n| n.distance).collect();
            let mean2 = (dists.iter().sum::<f64>() / dists.len().max(1) as f64).max(MIN_DIST2);
            (0.5 * mean2.ln()) as f32
        })
        .collect()
}

/// Opacity logit of a fresh Gaussian (0.1).
pub fn initial_opacity_logit() -> f32 {
    inverse_sigmoid(INIT_OPACITY)
}

/// INRIA `getNerfppNorm` radius: 1.1 × the largest distance of a camera centre from the mean
/// centre. The position learning rate (and densification thresholds) scale with it.
pub fn scene_extent(cameras: &[Camera]) -> Result<f64, TrainError> {
    if cameras.is_empty() {
        return Err(TrainError::Invalid("no cameras".into()));
    }
    let n = cameras.len() as f64;
    let mut mean = [0.0; 3];
    for c in cameras {
        let p = c.centre();
        (0..3).for_each(|a| mean[a] += p[a] / n);
    }
    let max = cameras
        .iter()
        .map(|c| {
            let p = c.centre();
            (0..3).map(|a| (p[a] - mean[a]).powi(2)).sum::<f64>().sqrt()
        })
        .fold(0.0, f64::max);
    let extent = 1.1 * max;
    // Zero would freeze the positions (their learning rate is relative to it).
    if !(extent > 0.0 && extent.is_finite()) {
        return Err(TrainError::Invalid(format!(
            "scene extent {extent} (need at least two distinct camera centres)"
        )));
    }
    Ok(extent)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn camera_at(p: [f64; 3]) -> Camera {
        let mut m = [[0.0; 4]; 4];
        (0..4).for_each(|i| m[i][i] = 1.0);
        (0..3).for_each(|i| m[i][3] = p[i]);
        Camera {
            fx: 10.0,
            fy: 10.0,
            cx: 5.0,
            cy: 5.0,
            width: 10,
            height: 10,
            world_from_camera: m,
        }
    }

    #[test]
    fn scales_come_from_the_three_nearest_neighbours() {
        // A point with neighbours at 0.1, 0.2, 0.2 and a far one it must ignore.
        let pts = [
            [0.0, 0.0, 0.0],
            [0.1, 0.0, 0.0],
            [0.0, 0.2, 0.0],
            [0.0, 0.0, -0.2],
            [5.0, 5.0, 5.0],
        ];
        let cols = [[0.5, 1.0, 0.0]; 5];
        let g = init_from_points(&pts, &cols).unwrap();
        let expected = ((0.01f64 + 0.04 + 0.04) / 3.0).sqrt().ln() as f32;
        assert!(
            (g.log_scales[0][0] - expected).abs() < 1e-6,
            "{:?}",
            g.log_scales[0]
        );
        assert_eq!(g.log_scales[0][0], g.log_scales[0][2]);
        assert!(g.log_scales[4][0] > 1.5, "the far point gets a large scale");
        assert_eq!(g.quats[0], [1.0, 0.0, 0.0, 0.0]);
        let opacity = 1.0 / (1.0 + (-g.opacity_logits[0]).exp());
        assert!((opacity - 0.1).abs() < 1e-6);
        assert_eq!(g.sh_degree, 0);
        assert_eq!(g.sh.len(), 15);
        // DC reproduces the colour: 0.5 + C0·dc.
        for (k, c) in [0.5, 1.0, 0.0].iter().enumerate() {
            assert!((0.5 + SH_C0 * g.sh[k] - c).abs() < 1e-6);
        }
        g.validate().unwrap();
    }

    #[test]
    fn duplicate_points_get_the_clamped_scale() {
        let g = init_from_points(&[[1.0; 3]; 3], &[[0.2; 3]; 3]).unwrap();
        assert!((g.log_scales[0][0] - (0.5 * 1e-7f64.ln()) as f32).abs() < 1e-5);
        assert!(init_from_points(&[[0.0; 3]], &[[0.0; 3]]).is_err());
        assert!(init_from_points(&[[0.0; 3]; 2], &[[0.0; 3]]).is_err());
    }

    #[test]
    fn extent_is_1_1_times_the_largest_centre_distance() {
        let cams = [
            camera_at([1.0, 0.0, 0.0]),
            camera_at([-1.0, 0.0, 0.0]),
            camera_at([0.0, 3.0, 0.0]),
        ];
        // Mean (0, 1, 0); farthest centre (0, 3, 0) at distance 2.
        assert!((scene_extent(&cams).unwrap() - 2.2).abs() < 1e-12);
        assert!(scene_extent(&cams[..1]).is_err());
    }
}
