//! Extra points (notes/method.md §8.1, Deblurring 3DGS): uniform candidates in the robust
//! bounding box of the cloud, coloured from their 4 nearest points, dropped when none is near.

use cocog_formats::PointCloud;
pub use cocog_formats::rng::SplitMix64;
use kiddo::{ImmutableKdTree, SquaredEuclidean};
use std::num::NonZero;

/// Neighbours interpolated per candidate (`pts_N_intpl`).
const NEIGHBOURS: usize = 4;
/// Points ignored at each end of every axis when choosing the box (`pts_add_bound`).
const TRIM: usize = 10;

/// The box between the `TRIM`-th smallest and largest coordinate on each axis, which keeps a
/// few outlier points from inflating it.
pub fn robust_box(cloud: &PointCloud) -> ([f64; 3], [f64; 3]) {
    let mut lo = [0.0; 3];
    let mut hi = [0.0; 3];
    for axis in 0..3 {
        let mut v: Vec<f64> = cloud
            .positions
            .iter()
            .skip(axis)
            .step_by(3)
            .map(|x| f64::from(*x))
            .collect();
        v.sort_by(f64::total_cmp);
        let trim = if v.len() > 2 * TRIM { TRIM } else { 0 };
        lo[axis] = v[trim];
        hi[axis] = v[v.len() - 1 - trim];
    }
    (lo, hi)
}

pub struct Extra {
    pub points: PointCloud,
    /// Candidates with no neighbour within `max_distance`.
    pub dropped: usize,
}

/// Draws `count` candidates and keeps those with a neighbour closer than `max_distance`.
/// A kept candidate's colour is `Σ w_k c_k` over its near neighbours with `w_k = d_k / Σ d`:
/// proportional to distance, not inverse, as the reference implementation does (kept for
/// fidelity; any convex combination of neighbour colours stays in their range).
pub fn extra_points(
    cloud: &PointCloud,
    count: usize,
    max_distance: f64,
    seed: u64,
    mut cancelled: impl FnMut(usize) -> bool,
) -> Option<Extra> {
    if cloud.is_empty() {
        return Some(Extra {
            points: PointCloud::default(),
            dropped: 0,
        });
    }
    let pts: Vec<[f64; 3]> = cloud
        .positions
        .chunks_exact(3)
        .map(|p| [p[0], p[1], p[2]].map(f64::from))
        .collect();
    let tree: ImmutableKdTree<f64, 3> = ImmutableKdTree::new_from_slice(&pts);
    let (lo, hi) = robust_box(cloud);
    let mut rng = SplitMix64::new(seed);
    let mut out = PointCloud {
        positions: Vec::with_capacity(3 * count),
        colors: Vec::with_capacity(3 * count),
    };
    let mut dropped = 0;
    let k = NonZero::new(NEIGHBOURS.min(pts.len())).expect("cloud is not empty");
    for i in 0..count {
        if i % 16384 == 0 && cancelled(i) {
            return None;
        }
        let p: [f64; 3] = std::array::from_fn(|a| lo[a] + (hi[a] - lo[a]) * rng.next_f64());
        let near: Vec<(f64, usize)> = tree
            .nearest_n::<SquaredEuclidean>(&p, k)
            .into_iter()
            .map(|n| (n.distance.sqrt(), n.item as usize))
            .filter(|(d, _)| *d < max_distance)
            .collect();
        if near.is_empty() {
            dropped += 1;
            continue;
        }
        let total: f64 = near.iter().map(|(d, _)| d).sum();
        let weight = |d: f64| {
            if total > 0.0 {
                d / total
            } else {
                1.0 / near.len() as f64
            }
        };
        let mut rgb = [0.0f64; 3];
        for (d, j) in &near {
            for (c, v) in rgb.iter_mut().enumerate() {
                *v += weight(*d) * f64::from(cloud.colors[3 * j + c]);
            }
        }
        out.positions.extend(p.map(|v| v as f32));
        out.colors
            .extend(rgb.map(|v| v.round().clamp(0.0, 255.0) as u8));
    }
    Some(Extra {
        points: out,
        dropped,
    })
}
