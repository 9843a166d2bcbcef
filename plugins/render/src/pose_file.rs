//! New cameras from a JSON file, in scene.json's convention: each has a `world_from_camera`
//! (4×4, row-major, OpenCV axes: x right, y down, z forward) and optionally the id of the
//! scene `camera` whose intrinsics it uses (default: the first training view's).

use std::path::Path;

use cocog_engine::Camera;
use cocog_formats::images::downscaled_size;
use cocog_pipeline::scene::check_pose;
use cocog_pipeline::{Scene, Split, StageError};
use serde::Deserialize;

use crate::NamedCamera;
use crate::cameras::output_stems;

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Pose {
    name: Option<String>,
    world_from_camera: [[f64; 4]; 4],
    camera: Option<u32>,
}

#[derive(Deserialize)]
#[serde(untagged)]
enum Poses {
    One(Pose),
    Many(Vec<Pose>),
}

/// The cameras `path` describes (one object or a list), at `downscale`.
pub fn cameras_from_file(
    path: &Path,
    scene: &Scene,
    scene_dir: &Path,
    downscale: u32,
) -> Result<Vec<NamedCamera>, StageError> {
    let text = std::fs::read_to_string(path).map_err(|e| StageError::io(path, e))?;
    let bad = |why: String| StageError::Input(format!("{}: {why}", path.display()));
    let poses = match serde_json::from_str::<Poses>(&text) {
        Ok(Poses::One(p)) => vec![p],
        Ok(Poses::Many(p)) => p,
        Err(_) => {
            // The untagged error says nothing useful; parse as a list of poses for the
            // field-level message.
            let e = serde_json::from_str::<Vec<Pose>>(&text)
                .err()
                .map_or_else(String::new, |e| e.to_string());
            return Err(bad(format!(
                "expected a camera {{\"world_from_camera\": 4×4 rows, \"camera\": scene \
                 camera id (optional), \"name\": text (optional)}} or a list of them ({e})"
            )));
        }
    };
    if poses.is_empty() {
        return Err(bad("the list of cameras is empty".into()));
    }
    let default_id = scene
        .views
        .iter()
        .find(|v| v.split == Split::Train)
        .or(scene.views.first())
        .map(|v| v.camera);
    let mut cams = poses
        .into_iter()
        .enumerate()
        .map(|(i, p)| {
            check_pose(&p.world_from_camera)
                .map_err(|why| bad(format!("camera {i}: world_from_camera {why}")))?;
            let id = p.camera.or(default_id).ok_or_else(|| {
                bad(format!(
                    "camera {i}: no `camera` id, and the scene has no views"
                ))
            })?;
            let cam = scene.camera(id).ok_or_else(|| {
                let ids: Vec<String> = scene.cameras.iter().map(|c| c.id.to_string()).collect();
                bad(format!(
                    "camera {i}: `camera` {id} is not a camera of {} (ids: {})",
                    scene_dir.join("scene.json").display(),
                    ids.join(", ")
                ))
            })?;
            let (w, h) = downscaled_size(cam.width, cam.height, downscale);
            let full = Camera {
                fx: cam.fx,
                fy: cam.fy,
                cx: cam.cx,
                cy: cam.cy,
                width: cam.width,
                height: cam.height,
                world_from_camera: p.world_from_camera,
            };
            Ok(NamedCamera {
                name: p.name.unwrap_or_else(|| format!("camera-{i:03}")),
                image: path.to_path_buf(),
                camera: full.resized(w, h),
                output: String::new(),
            })
        })
        .collect::<Result<Vec<_>, StageError>>()?;
    let names: Vec<&str> = cams.iter().map(|c| c.name.as_str()).collect();
    let stems = output_stems(&names);
    for (c, output) in std::iter::zip(&mut cams, stems) {
        c.output = output;
    }
    Ok(cams)
}
