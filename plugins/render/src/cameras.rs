//! The engine cameras of a scene's views, at a chosen downscale.

use std::path::{Path, PathBuf};

use cocog_engine::Camera;
use cocog_formats::images::downscaled_size;
use cocog_pipeline::{Scene, Split, StageError};

/// One view to render: its name, photo and camera.
#[derive(Clone, Debug)]
pub struct NamedCamera {
    /// The view's name (its image file name); outputs use its stem.
    pub name: String,
    /// The view's photo, resolved against the scene directory.
    pub image: PathBuf,
    pub camera: Camera,
}

impl NamedCamera {
    /// The view name without its extension: `000.png` → `000`.
    pub fn stem(&self) -> String {
        Path::new(&self.name)
            .file_stem()
            .map_or_else(|| self.name.clone(), |s| s.to_string_lossy().into_owned())
    }
}

/// `test`, `train` or `all` (None) from an option value.
pub fn parse_split(value: &str) -> Result<Option<Split>, StageError> {
    match value {
        "test" => Ok(Some(Split::Test)),
        "train" => Ok(Some(Split::Train)),
        "all" => Ok(None),
        other => Err(StageError::Options(format!(
            "option 'split': expected test, train or all, got {other:?}"
        ))),
    }
}

/// The option value naming `split`.
pub fn split_name(split: Split) -> &'static str {
    match split {
        Split::Test => "test",
        Split::Train => "train",
    }
}

/// Cameras of the views in `split` (all views for None), shrunk by `downscale` with every
/// intrinsic scaled by the size ratio (pixel-corner convention, as ingest and train do).
pub fn split_cameras(
    scene: &Scene,
    scene_dir: &Path,
    split: Option<Split>,
    downscale: u32,
) -> Result<Vec<NamedCamera>, StageError> {
    let views: Vec<_> = scene
        .views
        .iter()
        .filter(|v| split.is_none_or(|s| v.split == s))
        .collect();
    if views.is_empty() {
        let which = split.map_or("any", split_name);
        // Only render/eval choose the test split; train asks for its own and has no flag.
        let hint = if split == Some(Split::Test) {
            " (every view is a training view, e.g. ingested with --hold 0); to hold \
             some out, ingest again with --hold 8 (every 8th photo becomes a test view), or \
             use the training views with --split train (or --split all)"
        } else {
            ""
        };
        return Err(StageError::Input(format!(
            "{}: scene.json has no {which} views{hint}",
            scene_dir.display()
        )));
    }
    views
        .into_iter()
        .map(|view| {
            let cam = scene.camera(view.camera).ok_or_else(|| {
                StageError::Input(format!(
                    "{}: scene.json view {:?} names camera {}, which does not exist",
                    scene_dir.display(),
                    view.name,
                    view.camera
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
                world_from_camera: view.world_from_camera,
            };
            Ok(NamedCamera {
                name: view.name.clone(),
                image: Scene::resolve(scene_dir, &view.image),
                camera: full.resized(w, h),
            })
        })
        .collect()
}
