//! A dataset-free workload for speed measurements (`cocog bench --synthetic`): random
//! Gaussians filling a ball, seen by a ring of cameras around it, so step time at any
//! Gaussian count and resolution can be measured without photos. Every Gaussian is in front
//! of every camera and projects into its frame, so the whole count is rasterized in each view.

use cocog_engine::{Camera, GaussianParams, sh_coeffs_per_channel};
use glam::DVec3;

use crate::rig::look_at;
use crate::rng::Rng;

/// Radius of the ball the means fill.
pub const BALL_RADIUS: f64 = 1.0;
/// Distance of the cameras from the ball's centre.
pub const RING_RADIUS: f64 = 3.0;

/// The random Gaussians and the cameras of the ring.
#[derive(Clone, Debug)]
pub struct Workload {
    pub gaussians: GaussianParams,
    pub cameras: Vec<Camera>,
}

/// `count` Gaussians with full SH of `sh_degree`, `views` cameras of `width`×`height`. The
/// Gaussians' size follows their spacing (about a third of it per axis on average), so the
/// depth complexity per pixel stays realistic as the count grows, and their opacities span
/// 0.27–0.95; seeded and platform-independent.
pub fn random_workload(
    count: usize,
    width: u32,
    height: u32,
    views: usize,
    sh_degree: u32,
    seed: u64,
) -> Workload {
    let mut rng = Rng::fork(seed, 11);
    let spacing = BALL_RADIUS * (4.0 / 3.0 * std::f64::consts::PI / count.max(1) as f64).cbrt();
    let coeffs = sh_coeffs_per_channel(sh_degree);
    let mut g = GaussianParams {
        sh_degree,
        ..GaussianParams::default()
    };
    for _ in 0..count {
        let mean = loop {
            let p = DVec3::new(
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
            );
            if p.length_squared() <= 1.0 {
                break p * BALL_RADIUS;
            }
        };
        g.means.push(mean.as_vec3().to_array());
        g.log_scales
            .push([0; 3].map(|_| (spacing * rng.range(0.15, 0.5)).ln() as f32));
        let q = [0; 4].map(|_| rng.normal());
        let norm = q.iter().map(|v| v * v).sum::<f64>().sqrt().max(1e-9);
        g.quats.push(q.map(|v| (v / norm) as f32));
        g.opacity_logits.push(rng.range(-1.0, 3.0) as f32);
        // `sh[g][c][k]`: each channel's DC term, then its higher bands, smaller.
        for _channel in 0..3 {
            for k in 0..coeffs {
                let amplitude = if k == 0 { 1.5 } else { 0.1 };
                g.sh.push(rng.range(-amplitude, amplitude) as f32);
            }
        }
    }
    Workload {
        gaussians: g,
        cameras: ring(width, height, views),
    }
}

impl Workload {
    /// Multiplies every camera's focal length by `zoom` (≥ 1): each frame then sees the middle
    /// of the ball only, so part of the Gaussians fall outside it, as in a capture that
    /// surrounds the viewer, where most of the scene is beside or behind each camera.
    pub fn zoom(&mut self, zoom: f64) {
        for c in &mut self.cameras {
            c.fx *= zoom;
            c.fy *= zoom;
        }
    }

    /// The share of (Gaussian, camera) pairs whose mean projects into the frame.
    pub fn in_frame(&self) -> f64 {
        let mut inside = 0usize;
        for cam in &self.cameras {
            let m = cam.world_from_camera;
            for p in &self.gaussians.means {
                let d = [0, 1, 2].map(|i| f64::from(p[i]) - m[i][3]);
                // Camera axes are the rotation's columns: coordinates are dot products.
                let c = [0, 1, 2].map(|j| (0..3).map(|i| m[i][j] * d[i]).sum::<f64>());
                let u = cam.fx * c[0] / c[2] + cam.cx;
                let v = cam.fy * c[1] / c[2] + cam.cy;
                let frame = (0.0..f64::from(cam.width)).contains(&u)
                    && (0.0..f64::from(cam.height)).contains(&v);
                inside += usize::from(c[2] > 0.0 && frame);
            }
        }
        inside as f64 / (self.cameras.len() * self.gaussians.len()).max(1) as f64
    }
}

/// Cameras evenly around the ball at alternating heights, looking at its centre; the focal
/// length fits the ball into the shorter side of the frame.
fn ring(width: u32, height: u32, views: usize) -> Vec<Camera> {
    // The ball subtends asin(1/3) ≈ 19.5° off axis, tan ≈ 0.354: 0.4 leaves a margin.
    let focal = 0.5 * f64::from(width.min(height)) / 0.4;
    (0..views)
        .map(|k| {
            let angle = std::f64::consts::TAU * k as f64 / views.max(1) as f64;
            let height_off = if k % 2 == 0 { 0.3 } else { -0.3 };
            let centre = DVec3::new(angle.cos(), angle.sin(), height_off).normalize() * RING_RADIUS;
            Camera {
                fx: focal,
                fy: focal,
                cx: 0.5 * f64::from(width),
                cy: 0.5 * f64::from(height),
                width,
                height,
                world_from_camera: look_at(centre, DVec3::ZERO),
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Pixel position and depth of `p` in `cam`, by hand from `world_from_camera`.
    fn project(cam: &Camera, p: [f32; 3]) -> (f64, f64, f64) {
        let m = cam.world_from_camera;
        let d = [0, 1, 2].map(|i| f64::from(p[i]) - m[i][3]);
        // Camera axes are the rotation's columns: coordinates are dot products with them.
        let c = [0, 1, 2].map(|j| (0..3).map(|i| m[i][j] * d[i]).sum::<f64>());
        (
            cam.fx * c[0] / c[2] + cam.cx,
            cam.fy * c[1] / c[2] + cam.cy,
            c[2],
        )
    }

    #[test]
    fn every_gaussian_is_in_every_frame() {
        let w = random_workload(5000, 320, 180, 8, 3, 7);
        assert_eq!(w.gaussians.len(), 5000);
        w.gaussians.validate().unwrap();
        assert_eq!(w.gaussians.sh.len(), 5000 * 3 * 16);
        assert_eq!(w.cameras.len(), 8);
        for cam in &w.cameras {
            for &p in &w.gaussians.means {
                let (u, v, z) = project(cam, p);
                assert!(z >= RING_RADIUS - BALL_RADIUS - 1e-6, "depth {z}");
                assert!(
                    (0.0..320.0).contains(&u) && (0.0..180.0).contains(&v),
                    "({u}, {v})"
                );
            }
        }
        // The cameras surround the ball: their centres average to (nearly) its centre.
        let mean: f64 = (0..3)
            .map(|i| {
                w.cameras
                    .iter()
                    .map(|c| c.world_from_camera[i][3])
                    .sum::<f64>()
                    / 8.0
            })
            .map(f64::abs)
            .sum();
        assert!(mean < 1e-9, "{mean}");
    }

    /// Zooming leaves part of the ball out of every frame; `in_frame` agrees with a count by
    /// the hand projection above.
    #[test]
    fn zoom_leaves_part_of_the_ball_out_of_frame() {
        let mut w = random_workload(4000, 160, 90, 4, 0, 3);
        assert_eq!(w.in_frame(), 1.0);
        let before: Vec<f64> = w.cameras.iter().map(|c| c.fx).collect();
        w.zoom(3.0);
        let mut inside = 0;
        for (c, f) in w.cameras.iter().zip(before) {
            assert_eq!((c.fx, c.fy), (3.0 * f, 3.0 * f));
            for &p in &w.gaussians.means {
                let (u, v, z) = project(c, p);
                inside +=
                    usize::from(z > 0.0 && (0.0..160.0).contains(&u) && (0.0..90.0).contains(&v));
            }
        }
        let share = w.in_frame();
        assert_eq!(share, inside as f64 / 16000.0);
        assert!((0.1..0.6).contains(&share), "{share}");
    }

    #[test]
    fn sizes_follow_the_spacing_and_the_seed_decides_everything() {
        let small = random_workload(1000, 64, 48, 4, 0, 1);
        let large = random_workload(8000, 64, 48, 4, 0, 1);
        let mean_scale = |g: &GaussianParams| {
            g.log_scales
                .iter()
                .flatten()
                .map(|s| f64::from(*s).exp())
                .sum::<f64>()
                / (3 * g.len()) as f64
        };
        // Eight times the count halves the spacing, so the mean size.
        let ratio = mean_scale(&small.gaussians) / mean_scale(&large.gaussians);
        assert!((ratio - 2.0).abs() < 0.1, "{ratio}");
        let again = random_workload(1000, 64, 48, 4, 0, 1);
        assert_eq!(again.gaussians, small.gaussians);
        assert_ne!(
            random_workload(1000, 64, 48, 4, 0, 2).gaussians,
            small.gaussians
        );
    }
}
