//! COLMAP sparse models (`cameras`, `images`, `points3D`) in `.bin` and `.txt`.
//!
//! Records keep the file's order; ids are sparse, so never index by id.

mod bin;
mod check;
#[cfg(test)]
mod fuzz;
mod model;
mod txt;

use std::path::{Path, PathBuf};

pub use bin::{read_bin, write_bin};
pub use model::{CameraModel, Pinhole, pinhole};
pub use txt::{read_txt, write_txt};

pub(crate) use check::{focal as check_focal, show};

use crate::error::{FormatError, Result};
use crate::pose::{self, Mat4};

#[derive(Debug, Clone, PartialEq)]
pub struct Camera {
    pub id: u32,
    pub model: CameraModel,
    pub width: u64,
    pub height: u64,
    pub params: Vec<f64>,
}

impl Camera {
    /// Pinhole intrinsics, or why this camera has none (see [`pinhole`]).
    pub fn pinhole(&self) -> Result<Pinhole, String> {
        let p = pinhole(self.model, &self.params)?;
        check_focal("fx", p.fx, self.width as f64)?;
        check_focal("fy", p.fy, self.height as f64)?;
        Ok(p)
    }
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Point2D {
    pub xy: [f64; 2],
    /// `None` when the keypoint is not part of a track (u64::MAX in `.bin`, −1 in `.txt`).
    pub point3d_id: Option<u64>,
}

#[derive(Debug, Clone, PartialEq)]
pub struct Image {
    pub id: u32,
    /// `cam_from_world` rotation, Hamilton quaternion, w first.
    pub qvec: [f64; 4],
    /// `cam_from_world` translation.
    pub tvec: [f64; 3],
    pub camera_id: u32,
    pub name: String,
    pub points2d: Vec<Point2D>,
}

impl Image {
    /// The camera's pose in the world, OpenCV camera axes, row-major.
    pub fn world_from_camera(&self) -> Mat4 {
        pose::world_from_colmap(self.qvec, self.tvec)
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TrackElement {
    pub image_id: u32,
    pub point2d_idx: u32,
}

#[derive(Debug, Clone, PartialEq)]
pub struct Point3D {
    pub id: u64,
    pub xyz: [f64; 3],
    pub rgb: [u8; 3],
    /// Mean reprojection error in pixels; −1 when COLMAP never computed it.
    pub error: f64,
    pub track: Vec<TrackElement>,
}

#[derive(Debug, Clone, Default, PartialEq)]
pub struct Model {
    pub cameras: Vec<Camera>,
    pub images: Vec<Image>,
    pub points: Vec<Point3D>,
}

impl Model {
    pub fn camera(&self, id: u32) -> Option<&Camera> {
        self.cameras.iter().find(|c| c.id == id)
    }
}

/// Reads the model in `dir`, preferring `.bin` as COLMAP does when both are present.
pub fn read_model(dir: &Path) -> Result<Model> {
    if dir.join("cameras.bin").is_file() {
        read_bin(dir)
    } else if dir.join("cameras.txt").is_file() {
        read_txt(dir)
    } else {
        Err(FormatError::invalid(
            dir,
            "cameras",
            "no COLMAP model here: expected cameras.bin or cameras.txt (with images and points3D)",
        ))
    }
}

/// The file `read_model` reads for `stem` (`cameras`, `images` or `points3D`): the `.bin` one
/// when `cameras.bin` exists, else the `.txt` one; for naming it in messages.
pub fn model_file(dir: &Path, stem: &str) -> PathBuf {
    let ext = if dir.join("cameras.bin").is_file() {
        "bin"
    } else {
        "txt"
    };
    dir.join(format!("{stem}.{ext}"))
}

/// Number of registered images of the model in `dir`, read from the `images` header only.
fn image_count(dir: &Path) -> Result<usize> {
    let bin = dir.join("images.bin");
    if bin.is_file() {
        let mut f = std::fs::File::open(&bin).map_err(|e| FormatError::io(&bin, e))?;
        let mut n = [0u8; 8];
        std::io::Read::read_exact(&mut f, &mut n).map_err(|_| {
            FormatError::invalid(&bin, "num_reg_images", "file truncated: needs 8 bytes")
        })?;
        return Ok(u64::from_le_bytes(n) as usize);
    }
    Ok(read_model(dir)?.images.len())
}

/// Finds the sparse model of a scene: `<scene>/sparse/<index>` when given, else the `sparse/N`
/// with the most registered images (ties go to the lowest N), else `sparse/` itself if it holds a model.
pub fn find_model_dir(scene: &Path, index: Option<u32>) -> Result<PathBuf> {
    let sparse = scene.join("sparse");
    let has_model = |d: &Path| d.join("cameras.bin").is_file() || d.join("cameras.txt").is_file();
    if let Some(i) = index {
        let d = sparse.join(i.to_string());
        return if has_model(&d) {
            Ok(d)
        } else {
            Err(FormatError::invalid(
                &d,
                "model",
                "requested COLMAP model does not exist (no cameras.bin or cameras.txt)",
            ))
        };
    }
    let mut best: Option<(usize, u32, PathBuf)> = None;
    if let Ok(entries) = std::fs::read_dir(&sparse) {
        for entry in entries.flatten() {
            let Some(n) = entry
                .file_name()
                .to_str()
                .and_then(|s| s.parse::<u32>().ok())
            else {
                continue;
            };
            let d = entry.path();
            if !has_model(&d) {
                continue;
            }
            let count = image_count(&d)?;
            let better = best
                .as_ref()
                .is_none_or(|(bc, bn, _)| count > *bc || (count == *bc && n < *bn));
            if better {
                best = Some((count, n, d));
            }
        }
    }
    match best {
        Some((_, _, d)) => Ok(d),
        None if has_model(&sparse) => Ok(sparse),
        None => Err(FormatError::invalid(
            scene,
            "sparse",
            "no COLMAP model found: expected sparse/N/cameras.bin or .txt",
        )),
    }
}

/// Checks references between the three files: every image's camera exists. Values were
/// checked record by record as they were read.
/// `images_file` is the file the images were read from, for the message.
pub fn validate(model: &Model, images_file: &Path) -> Result<()> {
    for img in &model.images {
        if model.camera(img.camera_id).is_none() {
            return Err(FormatError::invalid(
                images_file,
                format!("image {} ({}).camera_id", img.id, img.name),
                format!("camera {} is not in cameras", img.camera_id),
            ));
        }
    }
    Ok(())
}
