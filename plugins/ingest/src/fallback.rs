//! Initial points for datasets that carry none (LLFF without `sparse/`, transforms.json).
//!
//! Training needs a starting cloud. With known depth bounds, points are spread through the
//! train views' frusta between near and far, uniform in disparity so near depths (where a
//! forward-facing scene has most of its detail per unit depth) get their share, as LLFF's
//! own NDC sampling does. Without bounds, INRIA 3DGS's rule for synthetic scenes is used:
//! a cube of side 2.6 around the origin. Colours are mid-grey; densify and training fix them.

use cocog_formats::PointCloud;
use cocog_pipeline::{Scene, Split};
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};

/// How many points the fallback draws (INRIA draws 100k for synthetic scenes).
pub(crate) const FALLBACK_POINTS: usize = 100_000;

pub(crate) fn fallback_points(scene: &Scene, count: usize, seed: u64) -> PointCloud {
    let mut rng = StdRng::seed_from_u64(seed);
    let mut cloud = PointCloud {
        positions: Vec::with_capacity(3 * count),
        colors: vec![128; 3 * count],
    };
    let train: Vec<_> = scene.views_in(Split::Train).collect();
    match (&scene.bounds, train.is_empty()) {
        (Some(b), false) => {
            let (near_disp, far_disp) = (1.0 / b.near.max(1e-6), 1.0 / b.far);
            for i in 0..count {
                let v = train[i % train.len()];
                let Some(cam) = scene.camera(v.camera) else {
                    continue;
                };
                let px = rng.random::<f64>() * f64::from(cam.width);
                let py = rng.random::<f64>() * f64::from(cam.height);
                let disp = near_disp + (far_disp - near_disp) * rng.random::<f64>();
                let z = 1.0 / disp;
                let local = [(px - cam.cx) / cam.fx * z, (py - cam.cy) / cam.fy * z, z];
                let m = &v.world_from_camera;
                for row in m.iter().take(3) {
                    let w = row[0] * local[0] + row[1] * local[1] + row[2] * local[2] + row[3];
                    cloud.positions.push(w as f32);
                }
            }
        }
        _ => {
            for _ in 0..3 * count {
                cloud
                    .positions
                    .push((rng.random::<f64>() * 2.6 - 1.3) as f32);
            }
        }
    }
    cloud.colors.truncate(cloud.positions.len());
    cloud
}

#[cfg(test)]
mod tests {
    use super::*;
    use cocog_pipeline::{Bounds, Camera, View};

    fn scene(bounds: Option<Bounds>) -> Scene {
        // A camera 2 units behind the origin on -z, looking down +z.
        let pose = [
            [1.0, 0.0, 0.0, 0.0],
            [0.0, 1.0, 0.0, 0.0],
            [0.0, 0.0, 1.0, -2.0],
            [0.0, 0.0, 0.0, 1.0],
        ];
        Scene {
            cameras: vec![Camera {
                id: 1,
                width: 40,
                height: 20,
                fx: 20.0,
                fy: 20.0,
                cx: 20.0,
                cy: 10.0,
            }],
            views: vec![View {
                name: "a.png".into(),
                image: "a.png".into(),
                camera: 1,
                world_from_camera: pose,
                split: Split::Train,
                lens: None,
                depth: None,
            }],
            bounds,
            ..Scene::default()
        }
    }

    #[test]
    fn points_fill_the_frustum_between_near_and_far() {
        let s = scene(Some(Bounds {
            near: 1.0,
            far: 4.0,
        }));
        let c = fallback_points(&s, 5000, 7);
        assert_eq!(c.len(), 5000);
        assert_eq!(c.colors.len(), 15000);
        let mut nearer_than_2 = 0;
        for p in c.positions.chunks_exact(3) {
            let z = f64::from(p[2]) + 2.0;
            assert!((1.0 - 1e-5..=4.0 + 1e-5).contains(&z), "depth {z}");
            // Inside the image: |x/z| <= cx/fx = 1, |y/z| <= cy/fy = 0.5.
            assert!(f64::from(p[0]).abs() <= z * 1.0 + 1e-5);
            assert!(f64::from(p[1]).abs() <= z * 0.5 + 1e-5);
            nearer_than_2 += usize::from(z < 2.0);
        }
        // Uniform in disparity: P(z < 2) = (1 - 1/2) / (1 - 1/4) = 2/3.
        let frac = nearer_than_2 as f64 / 5000.0;
        assert!(
            (frac - 2.0 / 3.0).abs() < 0.03,
            "fraction nearer than 2: {frac}"
        );
        assert_eq!(c, fallback_points(&s, 5000, 7), "same seed, same points");
    }

    #[test]
    fn without_bounds_points_fill_the_inria_cube() {
        let c = fallback_points(&scene(None), 1000, 1);
        assert_eq!(c.len(), 1000);
        assert!(c.positions.iter().all(|v| v.abs() <= 1.3));
        let spread = c.positions.iter().fold(0.0f32, |m, v| m.max(v.abs()));
        assert!(spread > 1.2, "points should reach the cube's faces");
    }
}
