//! The scene scale: the length the world-space density rules (clone/split boundary, large-
//! Gaussian prune) and the position learning rate are relative to.
//!
//! INRIA uses the camera extent (`scene_extent`), which measures how far the cameras move.
//! Around an object that is also how far away the object is, but on a forward-facing capture
//! the cameras move a few centimetres in front of a scene metres deep, so every rule scaled
//! by it treats the whole background as "large". The depth of what the cameras see does not
//! have that blind spot, and it is never smaller than the extent on captures around an object.

use cocog_engine::Camera;

use crate::{TrainError, scene_extent};

/// At most this many points are measured per camera: the median settles long before.
const MAX_POINTS: usize = 20_000;

/// The median over cameras of the median distance from the camera centre to the points in
/// front of it (all points, for a camera that has none in front). `None` without points.
pub fn median_depth(cameras: &[Camera], points: &[[f32; 3]]) -> Option<f64> {
    if points.is_empty() || cameras.is_empty() {
        return None;
    }
    let step = points.len().div_ceil(MAX_POINTS);
    let sample: Vec<[f64; 3]> = points
        .iter()
        .step_by(step)
        .filter(|p| p.iter().all(|v| v.is_finite()))
        .map(|p| p.map(f64::from))
        .collect();
    if sample.is_empty() {
        return None;
    }
    let mut per_camera: Vec<f64> = cameras
        .iter()
        .map(|cam| {
            let c = cam.centre();
            let m = &cam.world_from_camera;
            let forward = [m[0][2], m[1][2], m[2][2]];
            let offset = |p: &[f64; 3]| [p[0] - c[0], p[1] - c[1], p[2] - c[2]];
            let norm = |d: [f64; 3]| (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            let mut ahead: Vec<f64> = sample
                .iter()
                .map(offset)
                .filter(|d| d[0] * forward[0] + d[1] * forward[1] + d[2] * forward[2] > 0.0)
                .map(norm)
                .collect();
            if ahead.is_empty() {
                ahead = sample.iter().map(offset).map(norm).collect();
            }
            median(&mut ahead)
        })
        .collect();
    Some(median(&mut per_camera))
}

/// The larger of INRIA's camera extent and the median depth of the points (`median_depth`):
/// the extent on a capture around an object, the depth on a forward-facing one.
pub fn depth_scene_scale(cameras: &[Camera], points: &[[f32; 3]]) -> Result<f64, TrainError> {
    let extent = scene_extent(cameras)?;
    Ok(median_depth(cameras, points).map_or(extent, |d| d.max(extent)))
}

fn median(v: &mut [f64]) -> f64 {
    let mid = v.len() / 2;
    let (_, m, _) = v.select_nth_unstable_by(mid, f64::total_cmp);
    *m
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A camera at `eye` looking along +z (OpenCV axes).
    fn forward_camera(eye: [f64; 3]) -> Camera {
        let mut m = [[0.0; 4]; 4];
        for (i, row) in m.iter_mut().enumerate().take(3) {
            row[i] = 1.0;
            row[3] = eye[i];
        }
        m[3][3] = 1.0;
        Camera {
            fx: 100.0,
            fy: 100.0,
            cx: 50.0,
            cy: 40.0,
            width: 100,
            height: 80,
            world_from_camera: m,
        }
    }

    #[test]
    fn forward_facing_scale_is_the_depth_not_the_camera_spread() {
        // Cameras spread ±5 cm, points 1–3 m ahead: the extent is 5.5 cm, the depth ~2 m.
        let cams: Vec<Camera> = [-0.05, 0.0, 0.05]
            .iter()
            .map(|&x| forward_camera([x, 0.0, 0.0]))
            .collect();
        let points: Vec<[f32; 3]> = (0..=200)
            .map(|i| [0.0, 0.0, 1.0 + 2.0 * i as f32 / 200.0])
            .collect();
        let extent = scene_extent(&cams).unwrap();
        assert!((extent - 0.055).abs() < 1e-9, "{extent}");
        let depth = median_depth(&cams, &points).unwrap();
        // Median point at z = 2 m; the side cameras see it at √(2² + 0.05²).
        assert!((depth - 2.0f64.hypot(0.05)).abs() < 1e-6, "{depth}");
        assert_eq!(depth_scene_scale(&cams, &points).unwrap(), depth);
    }

    #[test]
    fn around_an_object_the_extent_wins_and_points_behind_are_ignored() {
        // Four cameras on a ring of radius 4 looking at a point cloud near the centre.
        let ring = |x: f64, z: f64| {
            let f = [-x / 4.0, 0.0, -z / 4.0];
            // Right = down × forward, with down = +y.
            let r = [-f[2], 0.0, f[0]];
            let mut m = [[0.0; 4]; 4];
            for i in 0..3 {
                m[i] = [r[i], [0.0, 1.0, 0.0][i], f[i], [x, 0.0, z][i]];
            }
            m[3][3] = 1.0;
            Camera {
                world_from_camera: m,
                ..forward_camera([0.0; 3])
            }
        };
        let cams = vec![
            ring(4.0, 0.0),
            ring(-4.0, 0.0),
            ring(0.0, 4.0),
            ring(0.0, -4.0),
        ];
        let points: Vec<[f32; 3]> = (0..100)
            .map(|i| {
                [
                    0.01 * (i % 10) as f32 - 0.05,
                    0.0,
                    0.01 * (i / 10) as f32 - 0.05,
                ]
            })
            .collect();
        let depth = median_depth(&cams, &points).unwrap();
        assert!((depth - 4.0).abs() < 0.1, "{depth}");
        assert!((depth_scene_scale(&cams, &points).unwrap() - 4.4).abs() < 1e-9);
        // A camera with everything behind it still gets a depth, from all points.
        let behind = vec![
            forward_camera([0.0, 0.0, 5.0]),
            forward_camera([0.1, 0.0, 5.0]),
        ];
        assert!((median_depth(&behind, &points).unwrap() - 5.0).abs() < 0.1);
        assert_eq!(median_depth(&behind, &[]), None);
    }
}
