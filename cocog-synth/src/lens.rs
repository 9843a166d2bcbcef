//! Thin-lens depth of field by aperture sampling over the f64 reference splatter.
//!
//! A thin lens focused at distance `s` images every point of the plane `z = s` (camera axes) to
//! the same pixel whatever part of the aperture its light passes through. So one lens render is
//! the mean of pinhole renders whose centre moves over the aperture disk while the image plane
//! stays parallel and its principal point shifts to keep that plane fixed (an off-axis
//! frustum). Unlike a blur filter this gets occlusion at depth edges right, as Cycles does.

use cocog_engine::Camera;
use cocog_engine::reference::{Gaussians64, render};

/// The lens of one view. Distances are scene units along the optical axis.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ThinLens {
    pub focus_distance: f64,
    pub aperture_radius: f64,
}

impl ThinLens {
    /// Circle-of-confusion diameter in pixels of a point at depth `z`: `2·A·fx·|1/z − 1/s|`.
    pub fn coc_px(&self, fx: f64, z: f64) -> f64 {
        2.0 * self.aperture_radius * fx * (1.0 / z - 1.0 / self.focus_distance).abs()
    }
}

/// How lens samples are averaged.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BlurSpace {
    /// Average radiance, i.e. sRGB-decoded values: what a real lens and Cycles do.
    Linear,
    /// Average the rendered (sRGB-encoded) values: what CoCoGaussian's model assumes.
    Display,
}

/// The golden angle in radians: successive samples never line up, so any prefix of the
/// pattern covers the disk evenly.
const GOLDEN_ANGLE: f64 = 2.399_963_229_728_653;

/// `n` points on the unit disk, area-uniform (a Vogel spiral): deterministic, no clumping.
pub fn aperture_pattern(n: usize) -> Vec<[f64; 2]> {
    (0..n)
        .map(|k| {
            let r = ((k as f64 + 0.5) / n as f64).sqrt();
            let th = k as f64 * GOLDEN_ANGLE;
            [r * th.cos(), r * th.sin()]
        })
        .collect()
}

/// The pinhole camera of one aperture sample at `offset` (scene units, camera x/y axes).
pub fn sample_camera(cam: &Camera, focus_distance: f64, offset: [f64; 2]) -> Camera {
    let m = &cam.world_from_camera;
    let mut out = *cam;
    for (r, row) in out.world_from_camera.iter_mut().take(3).enumerate() {
        row[3] = m[r][3] + m[r][0] * offset[0] + m[r][1] * offset[1];
    }
    out.cx = cam.cx + cam.fx * offset[0] / focus_distance;
    out.cy = cam.cy + cam.fy * offset[1] / focus_distance;
    out
}

pub fn srgb_to_linear(v: f64) -> f64 {
    let v = v.clamp(0.0, 1.0);
    if v <= 0.040_45 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

pub fn linear_to_srgb(v: f64) -> f64 {
    let v = v.clamp(0.0, 1.0);
    if v <= 0.003_130_8 {
        v * 12.92
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    }
}

/// Pinhole render, colour only, display (sRGB-encoded) values.
pub fn render_pinhole(g: &Gaussians64, cam: &Camera, background: [f64; 3]) -> Vec<[f64; 3]> {
    render(g, cam, background).color
}

/// Renders `cam` through `lens` with `samples` aperture samples; `None` (or a zero aperture)
/// is a plain pinhole render, bit-identical to `render_pinhole`.
pub fn render_thin_lens(
    g: &Gaussians64,
    cam: &Camera,
    lens: Option<ThinLens>,
    samples: usize,
    background: [f64; 3],
    space: BlurSpace,
) -> Vec<[f64; 3]> {
    let Some(lens) = lens.filter(|l| l.aperture_radius > 0.0 && samples > 0) else {
        return render_pinhole(g, cam, background);
    };
    type Transfer = fn(f64) -> f64;
    let (decode, encode): (Transfer, Transfer) = match space {
        BlurSpace::Linear => (srgb_to_linear, linear_to_srgb),
        BlurSpace::Display => (|v| v, |v| v),
    };
    let npix = (cam.width * cam.height) as usize;
    let mut acc = vec![[0.0; 3]; npix];
    for o in aperture_pattern(samples) {
        let offset = o.map(|v| v * lens.aperture_radius);
        let img = render_pinhole(
            g,
            &sample_camera(cam, lens.focus_distance, offset),
            background,
        );
        for (a, c) in acc.iter_mut().zip(&img) {
            for k in 0..3 {
                a[k] += decode(c[k]);
            }
        }
    }
    let inv = 1.0 / samples as f64;
    acc.iter().map(|a| a.map(|v| encode(v * inv))).collect()
}

/// 8-bit quantisation of display values, as PNG stores them.
pub fn quantize(color: &[[f64; 3]]) -> Vec<u8> {
    color
        .iter()
        .flat_map(|c| c.map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pattern_fills_the_disk_evenly() {
        let p = aperture_pattern(48);
        assert!(p.iter().all(|q| q[0].hypot(q[1]) <= 1.0));
        let mean = p.iter().fold([0.0, 0.0], |a, q| [a[0] + q[0], a[1] + q[1]]);
        assert!(mean[0].hypot(mean[1]) / 48.0 < 0.05, "{mean:?}");
        // Area-uniform: half the samples lie inside radius 1/√2.
        let inner = p
            .iter()
            .filter(|q| q[0].hypot(q[1]) < 0.5_f64.sqrt())
            .count();
        assert_eq!(inner, 24);
    }

    #[test]
    fn srgb_transfer_round_trips() {
        for i in 0..=100 {
            let v = f64::from(i) / 100.0;
            assert!((linear_to_srgb(srgb_to_linear(v)) - v).abs() < 1e-12);
        }
        assert!((srgb_to_linear(0.5) - 0.214_041).abs() < 1e-6);
    }

    #[test]
    fn sample_camera_keeps_the_focus_plane_fixed() {
        let cam = Camera {
            fx: 100.0,
            fy: 90.0,
            cx: 40.0,
            cy: 30.0,
            width: 80,
            height: 60,
            world_from_camera: [
                [0.0, 0.0, 1.0, 1.0],
                [-1.0, 0.0, 0.0, 2.0],
                [0.0, -1.0, 0.0, 3.0],
                [0.0, 0.0, 0.0, 1.0],
            ],
        };
        let project = |c: &Camera, p: [f64; 3]| {
            let (r, t) = c.camera_from_world();
            let q: [f64; 3] =
                std::array::from_fn(|i| r[i][0] * p[0] + r[i][1] * p[1] + r[i][2] * p[2] + t[i]);
            [c.fx * q[0] / q[2] + c.cx, c.fy * q[1] / q[2] + c.cy]
        };
        let s = 1.5;
        let shifted = sample_camera(&cam, s, [0.03, -0.02]);
        // Camera z is world +x here; this point is at depth s, off axis.
        let on_plane = [1.0 + s, 2.0 - 0.2, 3.0 + 0.1];
        let (a, b) = (project(&cam, on_plane), project(&shifted, on_plane));
        assert!((a[0] - b[0]).abs() < 1e-12 && (a[1] - b[1]).abs() < 1e-12);
        let off_plane = [1.0 + 2.0 * s, 2.0 - 0.2, 3.0 + 0.1];
        let (a, b) = (project(&cam, off_plane), project(&shifted, off_plane));
        assert!((a[0] - b[0]).abs() > 0.5);
    }
}
