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
    /// The stem its render is written under: see [`output_stems`].
    pub output: String,
}

impl NamedCamera {
    /// The view name without its extension: `000.png` → `000`.
    pub fn stem(&self) -> String {
        stem_of(&self.name)
    }
}

fn stem_of(name: &str) -> String {
    Path::new(name)
        .file_stem()
        .map_or_else(|| name.to_owned(), |s| s.to_string_lossy().into_owned())
}

/// Output file stems for views named `names`, one each and all different: the view's stem, or
/// where views share it (NeRF-synthetic's `train/r_0.png` and `test/r_0.png`) its whole name
/// without the extension, folders joined by `_`, and an index past that, so no render
/// overwrites another and renders still pair with their photos by name. A scene's views are
/// named over all its splits, so a view's render has one name whichever split is rendered.
pub fn output_stems(names: &[&str]) -> Vec<String> {
    let mut shared = std::collections::HashMap::new();
    for name in names {
        *shared.entry(stem_of(name)).or_insert(0u32) += 1;
    }
    let mut used = std::collections::HashSet::new();
    names
        .iter()
        .map(|name| {
            let stem = stem_of(name);
            let base = if shared[&stem] == 1 {
                stem
            } else {
                let whole = name.rsplit_once('.').map_or(*name, |(s, _)| s);
                whole.replace(['/', '\\'], "_")
            };
            let mut name = base.clone();
            let mut k = 1;
            while !used.insert(name.clone()) {
                name = format!("{base}-{k}");
                k += 1;
            }
            name
        })
        .collect()
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
    let names: Vec<&str> = scene.views.iter().map(|v| v.name.as_str()).collect();
    let views: Vec<_> = scene
        .views
        .iter()
        .zip(output_stems(&names))
        .filter(|(v, _)| split.is_none_or(|s| v.split == s))
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
        .map(|(view, output)| {
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
                output,
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn views_that_share_a_stem_get_distinct_output_names() {
        let names = [
            "train/r_0.png",
            "test/r_0.png",
            "r_1.png",
            "a.png",
            "a.png",
            "test_r_0.jpg",
        ];
        assert_eq!(
            output_stems(&names),
            ["train_r_0", "test_r_0", "r_1", "a", "a-1", "test_r_0-1"]
        );
        // Unique stems stay the plain stems that pair with photos by name.
        assert_eq!(output_stems(&["000.png", "008.png"]), ["000", "008"]);
    }
}
