//! Dataset readers: each turns one dataset layout into `RawView`s, points and bounds.

use std::path::Path;

use cocog_formats::colmap::{self, Model, Pinhole};
use cocog_formats::images::{image_size, list_images};
use cocog_formats::pose::{Mat4, invert_rigid};
use cocog_formats::{PointCloud, llff, nerf};
use cocog_pipeline::{Bounds, Split, StageError};

use crate::build::{Ingested, RawView};
use crate::input_error;

fn colmap_points(model: &Model) -> PointCloud {
    PointCloud {
        positions: model
            .points
            .iter()
            .flat_map(|p| p.xyz.map(|v| v as f32))
            .collect(),
        colors: model.points.iter().flat_map(|p| p.rgb).collect(),
    }
}

/// Near/far from the depths of each point in the images that observed it: 1 and 99
/// percentiles (LLFF uses 0.1/99.9; COLMAP outliers make that too wide), widened by 10 %.
fn bounds_from_model(model: &Model) -> Option<Bounds> {
    let cam_from_world: std::collections::HashMap<u32, Mat4> = model
        .images
        .iter()
        .map(|i| (i.id, invert_rigid(&i.world_from_camera())))
        .collect();
    let mut depths = Vec::new();
    for p in &model.points {
        for t in &p.track {
            if let Some(m) = cam_from_world.get(&t.image_id) {
                let z: f64 = (0..3).map(|k| m[2][k] * p.xyz[k]).sum::<f64>() + m[2][3];
                if z > 0.0 {
                    depths.push(z);
                }
            }
        }
    }
    if depths.len() < 2 {
        return None;
    }
    depths.sort_by(f64::total_cmp);
    let at = |q: f64| depths[((depths.len() - 1) as f64 * q).round() as usize];
    Some(Bounds {
        near: 0.9 * at(0.01),
        far: 1.1 * at(0.99),
    })
}

/// The dataset's image folder: `images/`, else Deblur-NeRF's `images_1/`.
fn image_dir(dataset: &Path) -> Result<std::path::PathBuf, StageError> {
    ["images", "images_1"]
        .iter()
        .map(|d| dataset.join(d))
        .find(|d| d.is_dir())
        .ok_or_else(|| {
            StageError::Input(format!(
                "{}: no images/ (or images_1/) folder",
                dataset.display()
            ))
        })
}

/// A COLMAP dataset: `sparse/N` (the one with most images unless `model` is given) plus `images/`.
pub(crate) fn read_colmap(
    dataset: &Path,
    model_index: Option<u32>,
) -> Result<Ingested, StageError> {
    let dir = colmap::find_model_dir(dataset, model_index).map_err(input_error)?;
    let model = colmap::read_model(&dir).map_err(input_error)?;
    let images = image_dir(dataset)?;
    from_colmap_model(&model, &dir, &images, dataset)
}

/// The views and points of a COLMAP model read from `dir`, photos in `images`, the `hold=N`
/// marker looked up in `dataset`.
pub(crate) fn from_colmap_model(
    model: &Model,
    dir: &Path,
    images: &Path,
    dataset: &Path,
) -> Result<Ingested, StageError> {
    let views = model
        .images
        .iter()
        .map(|img| {
            let source = format!(
                "{}: image {} ({:?})",
                colmap::model_file(dir, "images").display(),
                img.id,
                img.name
            );
            let cam = model.camera(img.camera_id).ok_or_else(|| {
                StageError::Input(format!("{source}: camera {} missing", img.camera_id))
            })?;
            let intrinsics = cam.pinhole().map_err(|e| {
                StageError::Input(format!(
                    "{}: camera {}: {e}",
                    colmap::model_file(dir, "cameras").display(),
                    cam.id
                ))
            })?;
            let size = (
                u32::try_from(cam.width).unwrap_or(u32::MAX),
                u32::try_from(cam.height).unwrap_or(u32::MAX),
            );
            Ok(RawView {
                name: img.name.clone(),
                image: images.join(&img.name),
                world_from_camera: img.world_from_camera(),
                intrinsics,
                size,
                split: None,
                depth: None,
                source,
            })
        })
        .collect::<Result<Vec<_>, StageError>>()?;
    let posed: std::collections::HashSet<&str> =
        model.images.iter().map(|i| i.name.as_str()).collect();
    // Advisory only: a folder that cannot be listed fails later, naming the photo it lacks.
    let unposed = list_images(images)
        .map(|files| {
            files
                .iter()
                .filter_map(|p| p.file_name()?.to_str())
                .filter(|name| !posed.contains(name))
                .map(str::to_owned)
                .collect()
        })
        .unwrap_or_default();
    Ok(Ingested {
        bounds: bounds_from_model(model),
        points: Some(colmap_points(model)),
        views,
        hold_marker: llff::read_hold_marker(dataset).map_err(input_error)?,
        unposed,
    })
}

/// An LLFF dataset: `poses_bounds.npy` rows in name order of `images/`. Points come from a
/// COLMAP model beside it when there is one (LLFF poses are that model's, same world frame).
pub(crate) fn read_llff(dataset: &Path) -> Result<Ingested, StageError> {
    let npy = dataset.join("poses_bounds.npy");
    let rows = llff::read_poses_bounds(&npy).map_err(input_error)?;
    let images = list_images(&image_dir(dataset)?).map_err(input_error)?;
    if rows.len() != images.len() {
        return Err(StageError::Input(format!(
            "{}: shape: {} rows, but the image folder has {} images (one row per name-sorted image)",
            npy.display(),
            rows.len(),
            images.len()
        )));
    }
    let mut views = Vec::with_capacity(rows.len());
    for (i, (row, image)) in rows.iter().zip(&images).enumerate() {
        let [h, w, f] = row.hwf;
        let size = (w.round() as u32, h.round() as u32);
        // LLFF assumes a centred principal point and square pixels.
        let intrinsics = Pinhole {
            fx: f,
            fy: f,
            cx: w / 2.0,
            cy: h / 2.0,
        };
        let name = image
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        views.push(RawView {
            name,
            image: image.clone(),
            world_from_camera: row.world_from_camera,
            intrinsics,
            size,
            split: None,
            depth: None,
            source: format!("{} row {i}", npy.display()),
        });
    }
    let near = rows.iter().map(|r| r.near).fold(f64::INFINITY, f64::min);
    let far = rows.iter().map(|r| r.far).fold(f64::NEG_INFINITY, f64::max);
    let points = match colmap::find_model_dir(dataset, None) {
        Ok(dir) => Some(colmap_points(
            &colmap::read_model(&dir).map_err(input_error)?,
        )),
        Err(_) => None,
    };
    Ok(Ingested {
        views,
        points,
        bounds: Some(Bounds { near, far }),
        hold_marker: llff::read_hold_marker(dataset).map_err(input_error)?,
        // One pose per photo, or the reader refused the folder.
        unposed: Vec::new(),
    })
}

/// A NeRF dataset: `transforms.json` or Blender's `transforms_{train,test}.json`. Frames keep
/// the file's split. Points only from the file's own `ply_file_path` (its world frame need not
/// match any COLMAP model beside it).
pub(crate) fn read_nerf(dataset: &Path) -> Result<Ingested, StageError> {
    let frames = nerf::read_dataset(dataset).map_err(input_error)?;
    let views = frames
        .iter()
        .map(|f| {
            let image = f.image_path(dataset);
            let source = format!(
                "{}: frames[{}] ({:?})",
                f.source.display(),
                f.index,
                f.file_path
            );
            // Blender files give no size: the intrinsics then describe the image as it is.
            let size = match (f.camera.w, f.camera.h) {
                (Some(w), Some(h)) => (w.round() as u32, h.round() as u32),
                _ => image_size(&image).map_err(|e| StageError::Input(format!("{source}: {e}")))?,
            };
            let intrinsics = f
                .camera
                .pinhole(f64::from(size.0), f64::from(size.1))
                .map_err(|e| StageError::Input(format!("{source}: {e}")))?;
            // A held-out frame is one no training sees, whatever the file calls it; a value
            // read as neither would quietly hand the whole split to the hold rule.
            let split = match f.split.as_deref() {
                Some("test" | "val") => Some(Split::Test),
                Some("train") => Some(Split::Train),
                None => None,
                Some(other) => {
                    return Err(StageError::Input(format!(
                        "{source}: split: expected \"train\" or \"test\" (\"val\" is held out \
                         too), got {other:?}"
                    )));
                }
            };
            let rel = f.file_path.trim_start_matches("./");
            let name = if Path::new(rel).extension().is_none() {
                format!("{rel}.png")
            } else {
                rel.to_owned()
            };
            Ok(RawView {
                name,
                image,
                world_from_camera: f.world_from_camera,
                intrinsics,
                size,
                split,
                depth: f.depth_file_path.as_ref().map(|d| dataset.join(d)),
                source,
            })
        })
        .collect::<Result<Vec<RawView>, StageError>>()?;
    // Name views by file name like the other layouts, unless that is ambiguous (Blender's
    // train/r_0 and test/r_0): then by the path as the file gives it.
    let base = |v: &RawView| {
        let n = Path::new(&v.name).file_name();
        n.map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default()
    };
    let mut bases: Vec<String> = views.iter().map(base).collect();
    bases.sort();
    let unique = bases.windows(2).all(|w| w[0] != w[1]);
    let views = views
        .into_iter()
        .map(|v| {
            if unique {
                RawView {
                    name: base(&v),
                    ..v
                }
            } else {
                v
            }
        })
        .collect();
    let points = match nerf::ply_file_path(dataset).map_err(input_error)? {
        Some(p) => Some(cocog_formats::ply::read_points(&p).map_err(input_error)?),
        None => None,
    };
    Ok(Ingested {
        views,
        points,
        bounds: None,
        hold_marker: llff::read_hold_marker(dataset).map_err(input_error)?,
        // transforms.json names its frames; other files beside them are not its photos.
        unposed: Vec::new(),
    })
}
