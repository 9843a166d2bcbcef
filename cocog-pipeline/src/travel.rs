//! A scene a stage writes carries its own model files: points, Gaussians and lens model that
//! it still references in an upstream scene are copied in, so deleting or moving that scene
//! does not break this one. Photos (and per-view depth) stay referenced where they are,
//! unless the user asks for a fully self-contained scene (`--copy-images`).

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use crate::scene::{Scene, SceneError};

/// Copies into `dir` every model file its scene.json references outside it (and, with
/// `photos`, every photo and depth map, into `images/` and `depth/`) and points the manifest
/// at the copies; returns how many were copied.
pub fn take_along(dir: &Path, photos: bool) -> Result<usize, SceneError> {
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
    if photos {
        copied += take_photos(dir, &home, &mut scene)?;
    }
    if copied > 0 {
        scene.save(dir)?;
    }
    Ok(copied)
}

/// Brings every view's photo and depth map under `dir`: hard links where the file system
/// allows (no extra space, and the copy survives deleting the original), copies elsewhere.
fn take_photos(dir: &Path, home: &Path, scene: &mut Scene) -> Result<usize, SceneError> {
    let mut copied = 0;
    let mut taken: HashMap<PathBuf, String> = HashMap::new();
    for view in &mut scene.views {
        for (slot, folder) in [
            (Some(&mut view.image), "images"),
            (view.depth.as_mut(), "depth"),
        ] {
            let Some(stored) = slot else {
                continue;
            };
            let src = Scene::resolve(dir, stored);
            let real = src.canonicalize().map_err(|source| SceneError::Io {
                path: src.clone(),
                source,
            })?;
            if real.starts_with(home) {
                continue;
            }
            if let Some(name) = taken.get(&real) {
                *stored = name.clone();
                continue;
            }
            let file = real
                .file_name()
                .map_or_else(|| "photo".into(), |n| n.to_string_lossy().into_owned());
            let sub = dir.join(folder);
            std::fs::create_dir_all(&sub).map_err(|source| SceneError::Io {
                path: sub.clone(),
                source,
            })?;
            // Photos from two folders may share a file name.
            let mut name = format!("{folder}/{file}");
            let mut k = 1;
            while dir.join(&name).exists() {
                name = format!("{folder}/{k}-{file}");
                k += 1;
            }
            let dst = dir.join(&name);
            if std::fs::hard_link(&real, &dst).is_err() {
                std::fs::copy(&real, &dst).map_err(|source| SceneError::Io {
                    path: real.clone(),
                    source,
                })?;
            }
            taken.insert(real, name.clone());
            *stored = name;
            copied += 1;
        }
    }
    Ok(copied)
}
