//! Plain parameter and camera types shared by the CPU reference and the GPU engine.

use crate::EngineError;

/// Side of a square screen tile in pixels; one rasterizer workgroup covers one tile.
pub const TILE_SIZE: u32 = 16;
/// Highest supported SH degree.
pub const MAX_SH_DEGREE: u32 = 3;
/// Gaussians closer than this (camera z) are culled.
pub const NEAR_PLANE: f64 = 0.01;
/// Added to the diagonal of every 2D covariance (the 3DGS low-pass filter).
pub const LOW_PASS: f64 = 0.3;
/// Per-Gaussian alpha ceiling and the cut-offs of 3DGS compositing.
pub const ALPHA_MAX: f64 = 0.99;
pub const ALPHA_MIN: f64 = 1.0 / 255.0;
pub const T_MIN: f64 = 1e-4;

/// Number of SH coefficients per colour channel for `degree` (DC included).
pub fn sh_coeffs_per_channel(degree: u32) -> usize {
    ((degree + 1) * (degree + 1)) as usize
}

/// One set of Gaussians, laid out like an INRIA 3DGS PLY so a loaded file maps 1:1:
/// `means` = x,y,z; `log_scales` = scale_0..2; `quats` = rot_0..3 (w,x,y,z, not normalised);
/// `opacity_logits` = opacity; `sh[g][c][k]` (channel-major, `k = 0` is f_dc_c and
/// `k = 1 + j` is f_rest_{c*K + j}).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct GaussianParams {
    pub sh_degree: u32,
    pub means: Vec<[f32; 3]>,
    pub log_scales: Vec<[f32; 3]>,
    pub quats: Vec<[f32; 4]>,
    pub opacity_logits: Vec<f32>,
    pub sh: Vec<f32>,
}

impl GaussianParams {
    pub fn len(&self) -> usize {
        self.means.len()
    }

    pub fn is_empty(&self) -> bool {
        self.means.is_empty()
    }

    /// Floats of SH per Gaussian (3 channels).
    pub fn sh_stride(&self) -> usize {
        3 * sh_coeffs_per_channel(self.sh_degree)
    }

    pub fn validate(&self) -> Result<(), EngineError> {
        let n = self.len();
        if self.sh_degree > MAX_SH_DEGREE {
            return Err(EngineError::Invalid(format!(
                "SH degree {} > {MAX_SH_DEGREE}",
                self.sh_degree
            )));
        }
        let lens = [
            self.log_scales.len(),
            self.quats.len(),
            self.opacity_logits.len(),
            self.sh.len() / self.sh_stride().max(1),
        ];
        if lens.iter().any(|&l| l != n) || self.sh.len() != n * self.sh_stride() {
            return Err(EngineError::Invalid(format!(
                "parameter arrays disagree on the Gaussian count ({n} means, lengths {lens:?}, {} SH floats)",
                self.sh.len()
            )));
        }
        Ok(())
    }
}

/// Pinhole camera. Pixel (i, j) has its centre at (i + 0.5, j + 0.5), the COLMAP convention.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
    pub width: u32,
    pub height: u32,
    /// Row-major 4×4 rigid transform, OpenCV axes (x right, y down, z forward).
    pub world_from_camera: [[f64; 4]; 4],
}

impl Camera {
    /// Rotation and translation of `camera_from_world`, the inverse of the rigid pose.
    pub fn camera_from_world(&self) -> ([[f64; 3]; 3], [f64; 3]) {
        let m = &self.world_from_camera;
        let mut r = [[0.0; 3]; 3];
        for (i, row) in r.iter_mut().enumerate() {
            for (j, v) in row.iter_mut().enumerate() {
                *v = m[j][i];
            }
        }
        let t = [m[0][3], m[1][3], m[2][3]];
        let tc = [
            -(r[0][0] * t[0] + r[0][1] * t[1] + r[0][2] * t[2]),
            -(r[1][0] * t[0] + r[1][1] * t[1] + r[1][2] * t[2]),
            -(r[2][0] * t[0] + r[2][1] * t[1] + r[2][2] * t[2]),
        ];
        (r, tc)
    }

    /// The same view at `width`×`height`: every intrinsic scales by the size ratio (pixel
    /// corners at integer coordinates, so the image edges stay where they were).
    pub fn resized(&self, width: u32, height: u32) -> Camera {
        let sx = f64::from(width) / f64::from(self.width);
        let sy = f64::from(height) / f64::from(self.height);
        Camera {
            fx: self.fx * sx,
            fy: self.fy * sy,
            cx: self.cx * sx,
            cy: self.cy * sy,
            width,
            height,
            world_from_camera: self.world_from_camera,
        }
    }

    pub fn centre(&self) -> [f64; 3] {
        let m = &self.world_from_camera;
        [m[0][3], m[1][3], m[2][3]]
    }

    pub fn tiles(&self) -> (u32, u32) {
        (
            self.width.div_ceil(TILE_SIZE),
            self.height.div_ceil(TILE_SIZE),
        )
    }
}

/// What one image of a batch renders: its Gaussians, camera and background colour.
#[derive(Clone, Copy, Debug)]
pub struct View<'a> {
    pub gaussians: &'a GaussianParams,
    pub camera: &'a Camera,
    pub background: [f32; 3],
}

/// Gradients with respect to every parameter of one `GaussianParams`, same layout.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct GaussianGrads {
    pub v_means: Vec<[f32; 3]>,
    pub v_log_scales: Vec<[f32; 3]>,
    pub v_quats: Vec<[f32; 4]>,
    pub v_opacity_logits: Vec<f32>,
    pub v_sh: Vec<f32>,
}

#[cfg(test)]
mod tests {
    use super::Camera;

    #[test]
    fn resizing_keeps_the_image_corners_in_place() {
        let cam = Camera {
            fx: 388.0,
            fy: 390.0,
            cx: 201.0,
            cy: 149.0,
            width: 400,
            height: 300,
            world_from_camera: [[0.0; 4]; 4],
        };
        let small = cam.resized(100, 75);
        assert_eq!((small.width, small.height), (100, 75));
        // A ray through the full image's corner pixel edge (400, 300) hits (100, 75).
        let (x, y) = ((400.0 - cam.cx) / cam.fx, (300.0 - cam.cy) / cam.fy);
        assert!((small.fx * x + small.cx - 100.0).abs() < 1e-12);
        assert!((small.fy * y + small.cy - 75.0).abs() < 1e-12);
        assert!((small.cx - 50.25).abs() < 1e-12);
    }
}
