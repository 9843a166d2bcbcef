//! After mapping: which of COLMAP's models to keep, and whether its cameras are distorted
//! enough to need `image_undistorter` (resampling every photo) or are pinholes in all but name.

use std::path::{Path, PathBuf};

use cocog_formats::colmap::{self, CameraModel, Model};
use cocog_pipeline::StageError;

use crate::input_error;

/// Largest shift, in pixels, that dropping a camera's distortion may cause anywhere in the
/// image and still count as a pinhole. Undistorting resamples every photo (a low-pass filter
/// on exactly the detail deblurring is about), so it is only worth it where the shift is
/// visible; a tenth of a pixel is well under COLMAP's own reprojection error (~0.3–1 px).
pub(crate) const PINHOLE_TOLERANCE_PX: f64 = 0.1;

pub(crate) struct Mapped {
    pub dir: PathBuf,
    pub model: Model,
}

/// Every model under `sparse/`, largest (most registered images) first; ties by index.
pub(crate) fn read_models(sparse: &Path) -> Result<Vec<Mapped>, StageError> {
    let mut dirs: Vec<(u32, PathBuf)> = std::fs::read_dir(sparse)
        .map_err(|e| StageError::io(sparse, e))?
        .flatten()
        .filter_map(|e| Some((e.file_name().to_str()?.parse().ok()?, e.path())))
        .filter(|(_, d): &(u32, PathBuf)| d.join("cameras.bin").is_file())
        .collect();
    dirs.sort();
    let mut models = dirs
        .into_iter()
        .map(|(_, dir)| {
            let model = colmap::read_model(&dir).map_err(input_error)?;
            Ok(Mapped { dir, model })
        })
        .collect::<Result<Vec<_>, StageError>>()?;
    models.sort_by_key(|m| std::cmp::Reverse(m.model.images.len()));
    Ok(models)
}

/// The largest pixel shift the camera's distortion causes at the image corners (where radial
/// and tangential terms peak for the models COLMAP fits here); `None` for models that are not
/// a pinhole plus polynomial distortion (fisheye and the like), which always need undistorting.
pub(crate) fn distortion_px(cam: &colmap::Camera) -> Option<f64> {
    use CameraModel as M;
    let p = &cam.params;
    let (fx, fy, cx, cy, k1, k2, p1, p2) = match cam.model {
        M::SimplePinhole => return Some(0.0),
        M::Pinhole => return Some(0.0),
        M::SimpleRadial => (p[0], p[0], p[1], p[2], p[3], 0.0, 0.0, 0.0),
        M::Radial => (p[0], p[0], p[1], p[2], p[3], p[4], 0.0, 0.0),
        M::OpenCv => (p[0], p[1], p[2], p[3], p[4], p[5], p[6], p[7]),
        _ => return None,
    };
    let (w, h) = (cam.width as f64, cam.height as f64);
    let corners = [(0.0, 0.0), (w, 0.0), (0.0, h), (w, h)];
    let shift = corners
        .iter()
        .map(|&(u, v)| {
            let (x, y) = ((u - cx) / fx, (v - cy) / fy);
            let r2 = x * x + y * y;
            let radial = k1 * r2 + k2 * r2 * r2;
            let dx = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x);
            let dy = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y;
            (dx * fx).hypot(dy * fy)
        })
        .fold(0.0, f64::max);
    Some(shift)
}

/// Rewrites every camera whose distortion stays under [`PINHOLE_TOLERANCE_PX`] as the pinhole
/// it then is. Returns the worst shift among all cameras, and whether some camera still needs
/// undistorting.
pub(crate) fn drop_small_distortion(model: &mut Model) -> (f64, bool) {
    let mut worst = 0.0f64;
    let mut needs_undistort = false;
    for cam in &mut model.cameras {
        match distortion_px(cam) {
            Some(px) if px <= PINHOLE_TOLERANCE_PX => {
                worst = worst.max(px);
                let p = &cam.params;
                let (fx, fy, cx, cy) = match cam.model {
                    CameraModel::OpenCv | CameraModel::Pinhole => (p[0], p[1], p[2], p[3]),
                    _ => (p[0], p[0], p[1], p[2]),
                };
                cam.model = CameraModel::Pinhole;
                cam.params = vec![fx, fy, cx, cy];
            }
            Some(px) => {
                worst = worst.max(px);
                needs_undistort = true;
            }
            None => {
                worst = f64::INFINITY;
                needs_undistort = true;
            }
        }
    }
    (worst, needs_undistort)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cam(model: CameraModel, params: Vec<f64>) -> colmap::Camera {
        colmap::Camera {
            id: 1,
            model,
            width: 400,
            height: 300,
            params,
        }
    }

    #[test]
    fn radial_shift_is_measured_at_the_corner() {
        // Corner (0, 0): normalised radius² = (200² + 150²) / 400² = 0.390625; the shift is
        // f·k·r³ = 400 · 0.01 · 0.390625^1.5 = 0.9765625 px.
        let c = cam(CameraModel::SimpleRadial, vec![400.0, 200.0, 150.0, 0.01]);
        assert!((distortion_px(&c).unwrap() - 0.9765625).abs() < 1e-9);
        let c = cam(CameraModel::SimpleRadial, vec![400.0, 200.0, 150.0, 1e-4]);
        let mut m = Model {
            cameras: vec![c],
            images: Vec::new(),
            points: Vec::new(),
        };
        let (worst, undistort) = drop_small_distortion(&mut m);
        assert!(!undistort && worst < PINHOLE_TOLERANCE_PX);
        assert_eq!(m.cameras[0].model, CameraModel::Pinhole);
        assert_eq!(m.cameras[0].params, vec![400.0, 400.0, 200.0, 150.0]);
    }

    #[test]
    fn tangential_terms_count_and_fisheye_always_undistorts() {
        let c = cam(
            CameraModel::OpenCv,
            vec![400.0, 400.0, 200.0, 150.0, 0.0, 0.0, 0.001, 0.0],
        );
        // Corner (0,0): x = -0.5, y = -0.375; dx = 2·p1·x·y = 3.75e-4, dy = p1·(r² + 2y²) =
        // 6.71875e-4; shift = 400·hypot = 0.30776 px.
        let px = distortion_px(&c).unwrap();
        assert!(
            (px - 400.0 * 3.75e-4f64.hypot(6.71875e-4)).abs() < 1e-9,
            "{px}"
        );
        let fish = cam(
            CameraModel::from_name("SIMPLE_RADIAL_FISHEYE").unwrap(),
            vec![400.0, 200.0, 150.0, 0.0],
        );
        assert_eq!(distortion_px(&fish), None);
    }
}
