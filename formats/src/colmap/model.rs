//! COLMAP camera models: ids, names, parameter counts, and reduction to pinhole intrinsics.

/// Every COLMAP camera model id as of COLMAP 4.1 (`src/colmap/sensor/models.h`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum CameraModel {
    SimplePinhole,
    Pinhole,
    SimpleRadial,
    Radial,
    OpenCv,
    OpenCvFisheye,
    FullOpenCv,
    Fov,
    SimpleRadialFisheye,
    RadialFisheye,
    ThinPrismFisheye,
    RadTanThinPrismFisheye,
    SimpleDivision,
    Division,
    SimpleFisheye,
    Fisheye,
    Eucm,
    Equirectangular,
}

const TABLE: [(CameraModel, &str, usize); 18] = [
    (CameraModel::SimplePinhole, "SIMPLE_PINHOLE", 3),
    (CameraModel::Pinhole, "PINHOLE", 4),
    (CameraModel::SimpleRadial, "SIMPLE_RADIAL", 4),
    (CameraModel::Radial, "RADIAL", 5),
    (CameraModel::OpenCv, "OPENCV", 8),
    (CameraModel::OpenCvFisheye, "OPENCV_FISHEYE", 8),
    (CameraModel::FullOpenCv, "FULL_OPENCV", 12),
    (CameraModel::Fov, "FOV", 5),
    (CameraModel::SimpleRadialFisheye, "SIMPLE_RADIAL_FISHEYE", 4),
    (CameraModel::RadialFisheye, "RADIAL_FISHEYE", 5),
    (CameraModel::ThinPrismFisheye, "THIN_PRISM_FISHEYE", 12),
    (
        CameraModel::RadTanThinPrismFisheye,
        "RAD_TAN_THIN_PRISM_FISHEYE",
        16,
    ),
    (CameraModel::SimpleDivision, "SIMPLE_DIVISION", 4),
    (CameraModel::Division, "DIVISION", 5),
    (CameraModel::SimpleFisheye, "SIMPLE_FISHEYE", 3),
    (CameraModel::Fisheye, "FISHEYE", 4),
    (CameraModel::Eucm, "EUCM", 6),
    (CameraModel::Equirectangular, "EQUIRECTANGULAR", 2),
];

impl CameraModel {
    pub const ALL: [CameraModel; 18] = {
        let mut all = [CameraModel::SimplePinhole; 18];
        let mut i = 0;
        while i < 18 {
            all[i] = TABLE[i].0;
            i += 1;
        }
        all
    };

    /// The id stored in `cameras.bin`.
    pub fn id(self) -> i32 {
        TABLE
            .iter()
            .position(|e| e.0 == self)
            .expect("every model is in TABLE") as i32
    }

    pub fn from_id(id: i32) -> Option<Self> {
        usize::try_from(id)
            .ok()
            .and_then(|i| TABLE.get(i))
            .map(|e| e.0)
    }

    /// The name used in `cameras.txt`.
    pub fn name(self) -> &'static str {
        TABLE[self.id() as usize].1
    }

    pub fn from_name(name: &str) -> Option<Self> {
        TABLE.iter().find(|e| e.1 == name).map(|e| e.0)
    }

    /// How many parameters the model has; `cameras.bin` does not store it.
    pub fn num_params(self) -> usize {
        TABLE[self.id() as usize].2
    }
}

/// Pinhole intrinsics in pixels, COLMAP pixel convention (the image corner is (0, 0)).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pinhole {
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
}

/// Reduces a camera to pinhole intrinsics.
///
/// Accepted: SIMPLE_PINHOLE, PINHOLE, and the perspective radial/OpenCV family (SIMPLE_RADIAL,
/// RADIAL, OPENCV, FULL_OPENCV) when every distortion coefficient is exactly zero, because those
/// are then the same projection. Refused: genuinely distorted cameras (a rasterizer cannot draw
/// them; run `colmap image_undistorter` first), and fisheye, FOV, division, EUCM and
/// equirectangular models, which are not perspective projections even with zero coefficients.
pub fn pinhole(model: CameraModel, params: &[f64]) -> Result<Pinhole, String> {
    use CameraModel as M;
    if params.len() != model.num_params() {
        return Err(format!(
            "{} needs {} parameters, got {}",
            model.name(),
            model.num_params(),
            params.len()
        ));
    }
    let (intr, distortion, names) = match model {
        M::SimplePinhole | M::SimpleRadial | M::Radial => (
            Pinhole {
                fx: params[0],
                fy: params[0],
                cx: params[1],
                cy: params[2],
            },
            &params[3..],
            &["f", "cx", "cy"][..],
        ),
        M::Pinhole | M::OpenCv | M::FullOpenCv => (
            Pinhole {
                fx: params[0],
                fy: params[1],
                cx: params[2],
                cy: params[3],
            },
            &params[4..],
            &["fx", "fy", "cx", "cy"][..],
        ),
        other => {
            return Err(format!(
                "camera model {} is not a perspective pinhole projection; undistort the images to PINHOLE first (colmap image_undistorter)",
                other.name()
            ));
        }
    };
    if let Some(k) = distortion.iter().find(|k| **k != 0.0) {
        return Err(format!(
            "camera model {} has non-zero distortion ({k}); undistort the images to PINHOLE first (colmap image_undistorter)",
            model.name()
        ));
    }
    for (k, (name, v)) in names.iter().zip(params).enumerate() {
        let focal = name.starts_with('f');
        if !v.is_finite() || (focal && *v <= 0.0) {
            let expected = if focal {
                "a focal length above 0 pixels"
            } else {
                "a finite number of pixels"
            };
            return Err(format!(
                "params[{k}] ({name}) of {} is {v}, expected {expected}",
                model.name()
            ));
        }
    }
    Ok(intr)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ids_names_and_counts_follow_colmap() {
        // Spot values from COLMAP's models.h, independent of the table's order.
        assert_eq!(
            CameraModel::from_id(4).map(CameraModel::name),
            Some("OPENCV")
        );
        assert_eq!(
            CameraModel::from_name("RAD_TAN_THIN_PRISM_FISHEYE").map(CameraModel::num_params),
            Some(16)
        );
        assert_eq!(
            CameraModel::from_name("EQUIRECTANGULAR").map(CameraModel::id),
            Some(17)
        );
        assert_eq!(CameraModel::from_id(18), None);
        assert_eq!(CameraModel::from_id(-1), None);
        for (i, m) in CameraModel::ALL.iter().enumerate() {
            assert_eq!(m.id() as usize, i);
            assert_eq!(CameraModel::from_name(m.name()), Some(*m));
        }
    }

    #[test]
    fn zero_distortion_reduces_and_real_distortion_is_refused() {
        let p = pinhole(
            CameraModel::OpenCv,
            &[500.0, 510.0, 320.0, 240.0, 0.0, 0.0, 0.0, 0.0],
        );
        assert_eq!(
            p,
            Ok(Pinhole {
                fx: 500.0,
                fy: 510.0,
                cx: 320.0,
                cy: 240.0
            })
        );
        let p = pinhole(CameraModel::SimpleRadial, &[500.0, 320.0, 240.0, 0.0]).unwrap();
        assert_eq!(p.fy, 500.0);
        let e = pinhole(CameraModel::SimpleRadial, &[500.0, 320.0, 240.0, 0.01]).unwrap_err();
        assert!(e.contains("non-zero distortion"), "{e}");
        let e = pinhole(CameraModel::Fisheye, &[500.0, 500.0, 320.0, 240.0]).unwrap_err();
        assert!(e.contains("not a perspective"), "{e}");
        assert!(pinhole(CameraModel::Pinhole, &[500.0, 320.0, 240.0]).is_err());
    }
}
