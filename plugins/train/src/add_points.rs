//! Deblurring 3DGS's point addition (method.md §8.1), which CoCoGaussian inherits at
//! iteration 2500: uniform candidates in the robust box of the current means, each taking the
//! SH of its nearest Gaussians, then every Gaussian re-initialised as if fresh from a cloud.

use std::num::NonZero;

use cocog_engine::GaussianParams;
use kiddo::{ImmutableKdTree, SquaredEuclidean};

use crate::SplitMix64;
use crate::init::{initial_opacity_logit, neighbour_log_scales};

/// Neighbours a candidate interpolates (`pts_N_intpl`).
const NEIGHBOURS: usize = 4;
/// Means ignored at each end of every axis when choosing the box (`pts_add_bound`).
const TRIM: usize = 10;
/// The candidate count is the initial cloud's box volume over this cubed (`pts_rate`).
const RATE: f64 = 1.1;

/// The units the rule's two constants are read in: the volume that sets how many points it
/// draws and the 2.0 cut-off distance. The released code reads them in its data's own units,
/// COLMAP's mapper output, which the mapper normalises so that the camera centres' robust box
/// is 10 across; there a forward-facing capture is hundreds of units deep and the count
/// reaches the cap (the supplementary's "approximately 200k points"). In a scene measured in
/// metres the same formula draws a handful.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PointsFrame {
    /// COLMAP's normalised frame, from the scene's cameras, held-out views included
    /// (`colmap_unit`). COLMAP 3.x's mapper normalises this way; newer mappers may keep the
    /// scale, but the released code's data (2023) are older.
    Colmap,
    /// The scene's own units, whatever they are.
    Scene,
}

impl PointsFrame {
    pub fn name(self) -> &'static str {
        match self {
            Self::Colmap => "colmap",
            Self::Scene => "scene",
        }
    }

    pub fn parse(name: &str) -> Option<Self> {
        match name {
            "colmap" => Some(Self::Colmap),
            "scene" => Some(Self::Scene),
            _ => None,
        }
    }

    /// One unit of this frame in scene units, for cameras centred at `centres`.
    pub fn unit(self, centres: &[[f64; 3]]) -> f64 {
        match self {
            Self::Colmap => colmap_unit(centres).unwrap_or(1.0),
            Self::Scene => 1.0,
        }
    }
}

/// The scene length that COLMAP's `Reconstruction::Normalize` (its defaults: extent 10,
/// percentiles 0.1 and 0.9 of the image centres) maps to one unit: the diagonal of the box
/// between those percentiles per axis, over 10. `None` when the box is degenerate.
pub fn colmap_unit(centres: &[[f64; 3]]) -> Option<f64> {
    let n = centres.len();
    if n == 0 {
        return None;
    }
    // COLMAP's indices: p·(n − 1), truncated, once there are more than 3 images.
    let (i0, i1) = if n > 3 {
        (
            (0.1 * (n - 1) as f64) as usize,
            (0.9 * (n - 1) as f64) as usize,
        )
    } else {
        (0, n - 1)
    };
    let diagonal = (0..3)
        .map(|a| {
            let mut v: Vec<f64> = centres.iter().map(|c| c[a]).collect();
            v.sort_by(f64::total_cmp);
            (v[i1] - v[i0]).powi(2)
        })
        .sum::<f64>()
        .sqrt();
    (diagonal.is_finite() && diagonal > 0.0).then_some(diagonal / 10.0)
}

/// How many points the rule adds at most: the initial cloud's box volume / 1.1³, capped.
pub fn candidate_count(initial_volume: f64, max: u32) -> usize {
    let n = initial_volume / RATE.powi(3);
    if n.is_finite() && n > 0.0 {
        n.min(f64::from(max)) as usize
    } else {
        0
    }
}

/// The product of the extents of the box around `means` (the rule's volume, in scene units³).
pub fn box_volume(means: &[[f32; 3]]) -> f64 {
    (0..3)
        .map(|a| {
            let (lo, hi) = means.iter().fold((f64::MAX, f64::MIN), |(lo, hi), p| {
                (lo.min(f64::from(p[a])), hi.max(f64::from(p[a])))
            });
            if hi > lo { hi - lo } else { 0.0 }
        })
        .product()
}

/// Per axis, the released code's `sorted[TRIM]` and `sorted[-TRIM]` (the extremes for few
/// means).
fn robust_box(means: &[[f32; 3]]) -> ([f64; 3], [f64; 3]) {
    let mut lo = [0.0; 3];
    let mut hi = [0.0; 3];
    for a in 0..3 {
        let mut v: Vec<f64> = means.iter().map(|p| f64::from(p[a])).collect();
        v.sort_by(f64::total_cmp);
        let trim = if v.len() > 2 * TRIM { TRIM } else { 0 };
        lo[a] = v[trim];
        hi[a] = v[v.len() - trim.max(1)];
    }
    (lo, hi)
}

/// `g` with up to `count` candidates added (those with a Gaussian within `max_distance`), and
/// every Gaussian, old and new, given the fresh-cloud shape: neighbour-distance isotropic
/// scale, identity rotation, opacity 0.1. Positions and SH of the old ones are kept. A kept
/// candidate's SH is `Σ w_k SH_k` over its near neighbours with `w_k = d_k / Σ d` —
/// proportional to distance, as the released code does (any convex combination stays in the
/// neighbours' range). Returns the new set and how many candidates were kept.
pub fn add_points(
    g: &GaussianParams,
    count: usize,
    max_distance: f64,
    rng: &mut SplitMix64,
) -> (GaussianParams, usize) {
    let mut out = g.clone();
    if g.len() < 2 {
        return (out, 0);
    }
    let stride = g.sh_stride();
    let pts: Vec<[f64; 3]> = g.means.iter().map(|p| p.map(f64::from)).collect();
    let tree: ImmutableKdTree<f64, 3> = ImmutableKdTree::new_from_slice(&pts);
    let k = NonZero::new(NEIGHBOURS.min(pts.len())).expect("at least two means");
    let (lo, hi) = robust_box(&g.means);
    let mut added = 0;
    for _ in 0..count {
        let p: [f64; 3] = std::array::from_fn(|a| lo[a] + (hi[a] - lo[a]) * rng.next_f64());
        let near: Vec<(f64, usize)> = tree
            .nearest_n::<SquaredEuclidean>(&p, k)
            .into_iter()
            .map(|n| (n.distance.sqrt(), n.item as usize))
            .filter(|(d, _)| *d < max_distance)
            .collect();
        if near.is_empty() {
            continue;
        }
        let total: f64 = near.iter().map(|(d, _)| d).sum();
        let mut sh = vec![0.0f64; stride];
        for &(d, j) in &near {
            // A candidate exactly on its neighbours (total 0) takes their plain mean.
            let w = if total > 0.0 {
                d / total
            } else {
                1.0 / near.len() as f64
            };
            for (s, v) in sh.iter_mut().zip(&g.sh[j * stride..(j + 1) * stride]) {
                *s += w * f64::from(*v);
            }
        }
        out.means.push(p.map(|v| v as f32));
        out.sh.extend(sh.iter().map(|v| *v as f32));
        added += 1;
    }
    let all: Vec<[f64; 3]> = out.means.iter().map(|p| p.map(f64::from)).collect();
    out.log_scales = neighbour_log_scales(&all)
        .into_iter()
        .map(|s| [s; 3])
        .collect();
    out.quats = vec![[1.0, 0.0, 0.0, 0.0]; all.len()];
    out.opacity_logits = vec![initial_opacity_logit(); all.len()];
    (out, added)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cloud(n: usize) -> GaussianParams {
        let mut rng = SplitMix64::new(3);
        let mut g = GaussianParams {
            sh_degree: 1,
            ..Default::default()
        };
        for _ in 0..n {
            g.means.push([0.0; 3].map(|_| rng.next_f64() as f32));
            g.log_scales.push([-2.0, -3.0, -4.0]);
            g.quats.push([0.5, 0.5, 0.5, 0.5]);
            g.opacity_logits.push(4.0);
            g.sh.extend((0..12).map(|_| rng.next_f64() as f32 - 0.5));
        }
        g
    }

    #[test]
    fn the_count_follows_the_initial_volume_and_its_cap() {
        assert_eq!(candidate_count(1332.0, 200_000), 1000);
        assert_eq!(candidate_count(1e9, 200_000), 200_000);
        assert_eq!(candidate_count(0.0, 200_000), 0);
        assert_eq!(candidate_count(f64::NAN, 200_000), 0);
        let v = box_volume(&[[0.0, 1.0, -1.0], [2.0, 4.0, 3.0], [1.0, 2.0, 0.0]]);
        assert!((v - 2.0 * 3.0 * 4.0).abs() < 1e-12);
    }

    #[test]
    fn candidates_interpolate_near_neighbours_and_everything_is_reinitialised() {
        let g = cloud(200);
        let mut rng = SplitMix64::new(9);
        let (out, added) = add_points(&g, 500, 0.2, &mut rng);
        assert!(
            added > 400,
            "most candidates in a dense unit cube are kept: {added}"
        );
        assert_eq!(out.len(), g.len() + added);
        assert_eq!(out.sh.len(), out.len() * g.sh_stride());
        // Old positions and SH are kept; the shapes are the fresh cloud's.
        assert_eq!(&out.means[..200], &g.means[..]);
        assert_eq!(&out.sh[..g.sh.len()], &g.sh[..]);
        assert!(out.quats.iter().all(|q| *q == [1.0, 0.0, 0.0, 0.0]));
        let logit = initial_opacity_logit();
        assert!(out.opacity_logits.iter().all(|o| *o == logit));
        assert!(out.log_scales.iter().all(|s| s[0] == s[1] && s[1] == s[2]));

        // Each new SH is the distance-weighted mix of its ≤ 4 neighbours within 0.2, checked
        // by brute force in f64.
        let stride = g.sh_stride();
        for i in 200..out.len() {
            let p = out.means[i].map(f64::from);
            let mut near: Vec<(f64, usize)> = g
                .means
                .iter()
                .enumerate()
                .map(|(j, q)| {
                    let d2: f64 = (0..3).map(|a| (p[a] - f64::from(q[a])).powi(2)).sum();
                    (d2.sqrt(), j)
                })
                .collect();
            near.sort_by(|a, b| a.0.total_cmp(&b.0));
            near.truncate(4);
            near.retain(|(d, _)| *d < 0.2);
            assert!(!near.is_empty());
            let total: f64 = near.iter().map(|n| n.0).sum();
            for c in 0..stride {
                let want: f64 = near
                    .iter()
                    .map(|(d, j)| d / total * f64::from(g.sh[j * stride + c]))
                    .sum();
                let got = f64::from(out.sh[i * stride + c]);
                assert!((got - want).abs() < 1e-5, "point {i} coefficient {c}");
            }
        }
    }

    #[test]
    fn candidates_with_no_near_gaussian_are_dropped() {
        let g = cloud(50);
        let (out, added) = add_points(&g, 300, 1e-9, &mut SplitMix64::new(1));
        assert_eq!((added, out.len()), (0, 50));
        // Re-initialisation still happens (the released code re-initialises every Gaussian).
        assert!(out.opacity_logits.iter().all(|o| *o < 0.0));
    }

    #[test]
    fn the_box_is_the_released_codes_tenth_from_either_end() {
        // Coordinates 0..100 on every axis, out of order: sorted[10] = 10, sorted[-10] = 90.
        let v: Vec<[f32; 3]> = (0..100).map(|i| [((i * 37) % 100) as f32; 3]).collect();
        assert_eq!(robust_box(&v), ([10.0; 3], [90.0; 3]));
        let few: Vec<[f32; 3]> = (0..20).map(|i| [i as f32, 0.0, -(i as f32)]).collect();
        assert_eq!(robust_box(&few), ([0.0, 0.0, -19.0], [19.0, 0.0, 0.0]));
    }

    #[test]
    fn the_colmap_unit_is_the_robust_camera_box_over_ten() {
        // 11 centres 0..10 along x (shuffled), y and z fixed: indices 1 and 9 → box 8 → 0.8.
        let line: Vec<[f64; 3]> = (0..11)
            .map(|i| [((i * 7) % 11) as f64, 2.0, -1.0])
            .collect();
        assert!((colmap_unit(&line).unwrap() - 0.8).abs() < 1e-12);
        // Ten uneven centres: indices ⌊0.1·9⌋ = 0 and ⌊0.9·9⌋ = 8, so 0 and 64 → 6.4.
        let uneven: Vec<[f64; 3]> = (0..10).map(|i| [(i * i) as f64, 0.0, 0.0]).collect();
        assert!((colmap_unit(&uneven).unwrap() - 6.4).abs() < 1e-12);
        // A diagonal: 3-4-0 per step, so the box's diagonal is 5 per step between them.
        let diag: Vec<[f64; 3]> = (0..21)
            .map(|i| [3.0 * i as f64, 4.0 * i as f64, 0.0])
            .collect();
        assert!((colmap_unit(&diag).unwrap() - 5.0 * 16.0 / 10.0).abs() < 1e-12);
        // Three cameras or fewer span their whole box; one camera has none.
        let few = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 2.0, 0.0]];
        assert!((colmap_unit(&few).unwrap() - 5f64.sqrt() / 10.0).abs() < 1e-12);
        assert_eq!(colmap_unit(&[[1.0, 2.0, 3.0]]), None);
        assert_eq!(PointsFrame::Colmap.unit(&[[1.0, 2.0, 3.0]]), 1.0);
        assert_eq!(PointsFrame::Scene.unit(&line), 1.0);
    }
}
