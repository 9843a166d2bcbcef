//! A scene a stage writes carries its own model files: points, Gaussians and lens model that
//! it still references in an upstream scene are copied in, so deleting or moving that scene
//! does not break this one. Photos (and per-view depth) stay referenced where they are.

use std::path::Path;

use crate::scene::{Scene, SceneError};

/// Copies into `dir` every model file its scene.json references outside it and points the
/// manifest at the copies; returns how many were copied.
pub fn take_along(dir: &Path) -> Result<usize, SceneError> {
    let io = |path: &Path| {
        let path = path.to_path_buf();
        move |source| SceneError::Io { path, source }
    };
    let mut scene = Scene::load(dir)?;
    let home = dir.canonicalize().map_err(io(dir))?;
    let mut copied = 0;
    for slot in [
        &mut scene.points,
        &mut scene.gaussians,
        &mut scene.lens_model,
    ] {
        let Some(stored) = slot.as_mut() else {
            continue;
        };
        let src = Scene::resolve(dir, stored);
        // A missing file is the reading stage's error to report, with its own context.
        let Ok(real) = src.canonicalize() else {
            continue;
        };
        if real.starts_with(&home) || !real.is_file() {
            continue;
        }
        let name = real
            .file_name()
            .map_or_else(|| "model".into(), |n| n.to_string_lossy().into_owned());
        // The stage may have written its own file of that name (train's gaussians.ply).
        let name = if dir.join(&name).exists() {
            format!("input-{name}")
        } else {
            name
        };
        let dst = dir.join(&name);
        std::fs::copy(&real, &dst).map_err(io(&real))?;
        *stored = name;
        copied += 1;
    }
    if copied > 0 {
        scene.save(dir)?;
    }
    Ok(copied)
}
