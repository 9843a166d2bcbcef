//! Scene → trainer inputs: the initial Gaussians from `points.ply` and the views of a split.

use std::path::Path;

use cocog_engine::GaussianParams;
use cocog_formats::images::{load_rgb, write_downscaled};
use cocog_pipeline::{Context, Scene, Split, StageError, StageRequest};

use crate::{TrainConfig, TrainView, init_from_points};

/// Reads the scene's point cloud (the `points` field of scene.json) and initialises Gaussians.
pub fn initial_gaussians(scene: &Scene, input: &Path) -> Result<GaussianParams, StageError> {
    let stored = scene.points.as_deref().ok_or_else(|| {
        StageError::Input(format!(
            "{}: scene.json has no field `points`; training starts from a point cloud \
             (run an ingest stage that writes points.ply)",
            input.display()
        ))
    })?;
    let path = Scene::resolve(input, stored);
    let cloud = cocog_formats::ply::read_points(&path)
        .map_err(|e| StageError::Input(format!("scene.json `points`: {e}")))?;
    let positions: Vec<[f32; 3]> = cloud
        .positions
        .chunks_exact(3)
        .map(|p| [p[0], p[1], p[2]])
        .collect();
    // The images are trained on as stored (sRGB-encoded), so colours stay in that space too,
    // as INRIA does with the SfM colours / 255.
    let colors: Vec<[f32; 3]> = cloud
        .colors
        .chunks_exact(3)
        .map(|c| [c[0], c[1], c[2]].map(|v| f32::from(v) / 255.0))
        .collect();
    init_from_points(&positions, &colors)
        .map_err(|e| StageError::Input(format!("{}: {e}", path.display())))
}

/// `split_views` with its scratch folder inside the output, removed before returning.
pub fn views_scratch(
    scene: &Scene,
    req: &StageRequest,
    split: Split,
    downscale: u32,
    config: &TrainConfig,
    ctx: &dyn Context,
) -> Result<Vec<TrainView>, StageError> {
    let scratch = req.output.join(".downscaled");
    if downscale > 1 {
        std::fs::create_dir_all(&scratch).map_err(|e| StageError::io(&scratch, e))?;
    }
    let views = split_views(
        scene,
        &req.input,
        split,
        downscale,
        config.background,
        &scratch,
        ctx,
    );
    if downscale > 1 {
        std::fs::remove_dir_all(&scratch).map_err(|e| StageError::io(&scratch, e))?;
    }
    views
}

/// Loads every view of `split`, shrunk by `downscale` with intrinsics scaled to match.
/// `scratch` holds the downscaled PNGs (formats' area filter only writes files); the caller
/// removes it.
pub fn split_views(
    scene: &Scene,
    input: &Path,
    split: Split,
    downscale: u32,
    background: [f32; 3],
    scratch: &Path,
    ctx: &dyn Context,
) -> Result<Vec<TrainView>, StageError> {
    let views = cocog_render::split_cameras(scene, input, Some(split), downscale)?;
    let total = views.len() as u64;
    let task = match split {
        Split::Train => "load images",
        Split::Test => "load test images",
    };
    let mut out = Vec::with_capacity(views.len());
    for (i, view) in views.iter().enumerate() {
        ctx.check_cancelled()?;
        ctx.progress(task, i as u64, total);
        let (w, h) = (view.camera.width, view.camera.height);
        let src = &view.image;
        let path = if downscale > 1 {
            let dst = scratch.join(format!("{i}.png"));
            write_downscaled(src, &dst, downscale)
                .map_err(|e| StageError::Input(format!("view {:?}: {e}", view.name)))?;
            dst
        } else {
            src.clone()
        };
        let img = load_rgb(&path, Some(background))
            .map_err(|e| StageError::Input(format!("view {:?}: {e}", view.name)))?;
        if (img.width, img.height) != (w, h) {
            return Err(StageError::Input(format!(
                "{}: image is {}×{} after downscale {downscale}, but the camera of view {:?} is {w}×{h}",
                src.display(),
                img.width,
                img.height,
                view.name
            )));
        }
        out.push(TrainView {
            camera: view.camera,
            image: img
                .data
                .chunks_exact(3)
                .map(|p| [p[0], p[1], p[2]])
                .collect(),
        });
    }
    ctx.progress(task, total, total);
    Ok(out)
}

/// Known focus distances (scene units), one per training view in the scene's order, from a
/// transforms.json whose frames carry `focus_distance_m` (the cocog bench and demo datasets;
/// a converter can write a camera's EXIF subject distance there). Frames match views by file
/// name; every training view must have one.
pub fn known_focus(scene: &Scene, path: &Path) -> Result<Vec<f64>, StageError> {
    let frames = cocog_formats::nerf::read_transforms(path, None)
        .map_err(|e| StageError::Input(format!("option 'focus_init': {e}")))?;
    let by_name: std::collections::HashMap<String, Option<f64>> = frames
        .iter()
        .map(|f| (f.image_name(), f.focus_distance))
        .collect();
    let mut known = Vec::new();
    let mut missing = Vec::new();
    for v in scene.views.iter().filter(|v| v.split == Split::Train) {
        let stem = |n: &str| {
            Path::new(n)
                .with_extension("")
                .to_string_lossy()
                .into_owned()
        };
        let found = by_name
            .get(&v.name)
            .or_else(|| {
                by_name
                    .iter()
                    .find(|(k, _)| stem(k) == stem(&v.name))
                    .map(|e| e.1)
            })
            .copied()
            .flatten()
            .filter(|d| d.is_finite() && *d > 0.0);
        match found {
            Some(d) => known.push(d),
            None => missing.push(v.name.clone()),
        }
    }
    if !missing.is_empty() {
        let shown: Vec<&str> = missing.iter().take(5).map(String::as_str).collect();
        return Err(StageError::Input(format!(
            "option 'focus_init': {} has no positive `focus_distance_m` for {} training view(s): \
             {}{}",
            path.display(),
            missing.len(),
            shown.join(", "),
            if missing.len() > 5 { ", ..." } else { "" }
        )));
    }
    Ok(known)
}
