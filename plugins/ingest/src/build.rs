//! Turns the views a dataset reader found into a scene directory: split, image checks,
//! optional downscaling, camera de-duplication, up vector, points and bounds.

use std::path::{Path, PathBuf};

use cocog_formats::PointCloud;
use cocog_formats::colmap::Pinhole;
use cocog_formats::images::{downscaled_size, image_size, prescaled_path, write_downscaled};
use cocog_formats::pose::Mat4;
use cocog_pipeline::{Bounds, Camera, Context, Scene, Split, StageError, View};
use glam::DVec3;
use serde_json::{Value, json};

use crate::fallback::{FALLBACK_POINTS, fallback_points};
use crate::input_error;
use crate::paths::check_inside;

/// One view as a reader found it, before any checks.
pub(crate) struct RawView {
    /// View name and sort key: the image name as the dataset lists it.
    pub name: String,
    /// The full-resolution image.
    pub image: PathBuf,
    pub world_from_camera: Mat4,
    /// Intrinsics for an image of `size` pixels.
    pub intrinsics: Pinhole,
    pub size: (u32, u32),
    /// The split the dataset itself declares, if any.
    pub split: Option<Split>,
    pub depth: Option<PathBuf>,
    /// Where the view was declared, for error messages.
    pub source: String,
}

pub(crate) struct Ingested {
    pub views: Vec<RawView>,
    pub points: Option<PointCloud>,
    pub bounds: Option<Bounds>,
    /// The `hold=N` marker of the dataset, if present.
    pub hold_marker: Option<u32>,
    /// Photos in the image folder that the dataset poses nowhere (a COLMAP model that did not
    /// register them). The hold rule counts posed views only, as the reference code does.
    pub unposed: Vec<String>,
}

pub(crate) struct Settings {
    pub downscale: u32,
    /// `None`: the dataset's own split (per-frame splits, else the hold=N marker, else 8).
    /// `Some(0)`: every view trains. `Some(n)`: every n-th view in name order is a test view.
    pub hold: Option<u32>,
    /// Accept image and depth paths that lead outside the dataset folder.
    pub allow_outside: bool,
}

/// Refusals that need no image read, so a bad dataset or option fails before any work.
fn preflight(
    dataset: &Path,
    out: &Path,
    views: &[RawView],
    settings: &Settings,
) -> Result<(), StageError> {
    for raw in views {
        // Photos the stage itself wrote into the output (undistorted) are not the dataset's.
        if !settings.allow_outside && !raw.image.starts_with(out) {
            check_inside(dataset, &raw.image, "image", &raw.source)?;
            if let Some(depth) = &raw.depth {
                check_inside(dataset, depth, "depth", &raw.source)?;
            }
        }
        let (w, h) = raw.size;
        if settings.downscale > w.min(h) {
            return Err(StageError::Options(format!(
                "option 'downscale': {} would shrink the {w}×{h} image of view {:?} (from {}) below 1×1 pixel; expected at most {}",
                settings.downscale,
                raw.name,
                raw.source,
                w.min(h)
            )));
        }
    }
    Ok(())
}

fn absolute(p: &Path) -> String {
    std::fs::canonicalize(p)
        .unwrap_or_else(|_| p.to_path_buf())
        .to_string_lossy()
        .into_owned()
}

/// Unit vector opposite the mean camera "down" axis: OpenCV cameras have +y down.
fn estimate_up(views: &[View]) -> Option<[f64; 3]> {
    let sum: DVec3 = views
        .iter()
        .map(|v| {
            -DVec3::new(
                v.world_from_camera[0][1],
                v.world_from_camera[1][1],
                v.world_from_camera[2][1],
            )
        })
        .sum();
    (sum.length() > 1e-9).then(|| sum.normalize().to_array())
}

/// Says when a dataset's `images_N/` was there but not used for every photo: its names must
/// match `images/`'s (stock LLFF scenes rename them), and the rest were resampled, which is
/// what the reference code does anyway but not what a user who made `images_N/` expects.
fn warn_resampled(
    dataset: &Path,
    factor: u32,
    resampled: &[&str],
    views: usize,
    ctx: &dyn Context,
) {
    let dir = dataset.join(format!("images_{factor}"));
    if resampled.is_empty() || !dir.is_dir() {
        return;
    }
    ctx.warn(&format!(
        "{}: {} of {views} photos have no file of the same name there (first: {}); those were \
         area-downscaled from the full-size photos instead",
        dir.display(),
        resampled.len(),
        resampled[0]
    ));
}

/// Says which photos the hold rule skipped: on Deblur-NeRF data the held-out views are the sharp
/// ones, and a photo the model lacks shifts every later index, so blurred photos can become
/// test views without any other sign.
fn warn_unposed(dataset: &Path, unposed: &[String], scene: &Scene, hold: u32, ctx: &dyn Context) {
    const LISTED: usize = 5;
    let mut names = unposed
        .iter()
        .take(LISTED)
        .cloned()
        .collect::<Vec<_>>()
        .join(", ");
    if unposed.len() > LISTED {
        names += &format!(" and {} more", unposed.len() - LISTED);
    }
    let tests: Vec<&str> = scene
        .views_in(Split::Test)
        .map(|v| v.name.as_str())
        .collect();
    ctx.warn(&format!(
        "{}: {} photo(s) in the image folder have no pose in the model ({names}); the hold rule \
         (test views at indices that are multiples of {hold}) counts the {} posed views, as the \
         reference code does, so the test views are {}: check they are the ones you meant to \
         hold out (--hold N changes the rule)",
        dataset.display(),
        unposed.len(),
        scene.views.len(),
        tests.join(", ")
    ));
}

/// Builds the scene in `out` (an existing, empty directory). Returns it and a summary.
pub(crate) fn build_scene(
    dataset: &Path,
    mut data: Ingested,
    settings: &Settings,
    out: &Path,
    ctx: &dyn Context,
) -> Result<(Scene, Value), StageError> {
    if data.views.is_empty() {
        return Err(StageError::Input(format!(
            "{}: the dataset has no views",
            dataset.display()
        )));
    }
    data.views.sort_by(|a, b| a.name.cmp(&b.name));
    if let Some(w) = data.views.windows(2).find(|w| w[0].name == w[1].name) {
        return Err(StageError::Input(format!(
            "{}: two views are named {:?}",
            w[1].source, w[1].name
        )));
    }
    preflight(dataset, out, &data.views, settings)?;
    let declared = data.views.iter().all(|v| v.split.is_some());
    let hold = settings.hold.or(data.hold_marker).unwrap_or(8);
    let use_declared = settings.hold.is_none() && declared;
    if hold == 1 && !use_declared {
        let why = "makes every view a test view, leaving none to train on: use --hold 8 (every \
                   8th view held out) or --hold 0 (every view trains)";
        // The option is the user's mistake (a usage error); the marker is the dataset's.
        return Err(if settings.hold.is_some() {
            StageError::Options(format!("--hold 1 {why}"))
        } else {
            StageError::Input(format!("{}'s hold=1 marker {why}", dataset.display()))
        });
    }
    let some = data.views.iter().filter(|v| v.split.is_some()).count();
    if settings.hold.is_none() && !declared && some > 0 {
        let missing = data.views.iter().find(|v| v.split.is_none());
        ctx.warn(&format!(
            "{some} of {} views declare a split, but not all ({} has none): the hold rule \
             decides every view's split instead",
            data.views.len(),
            missing.map_or("one", |v| v.source.as_str())
        ));
    }
    let n = data.views.len() as u64;
    let mut scene = Scene::default();
    let mut written = std::collections::HashSet::new();
    let mut resampled = Vec::new();
    for (i, raw) in data.views.iter().enumerate() {
        ctx.check_cancelled()?;
        ctx.progress("check images", i as u64, n);
        let full = image_size(&raw.image).map_err(|e| {
            StageError::Input(format!("view {:?} (from {}): {e}", raw.name, raw.source))
        })?;
        if full != raw.size {
            return Err(StageError::Input(format!(
                "{}: image is {}×{} but the camera of view {:?} (from {}) is {}×{}",
                raw.image.display(),
                full.0,
                full.1,
                raw.name,
                raw.source,
                raw.size.0,
                raw.size.1
            )));
        }
        let (image, size) =
            if let (1, Ok(inside)) = (settings.downscale, raw.image.strip_prefix(out)) {
                // Relative: the output folder is renamed into place when the stage commits.
                (inside.to_string_lossy().into_owned(), full)
            } else if settings.downscale <= 1 {
                (absolute(&raw.image), full)
            } else if let Some(pre) = prescaled_path(dataset, &raw.image, settings.downscale) {
                let size = image_size(&pre).map_err(input_error)?;
                let want = downscaled_size(full.0, full.1, settings.downscale);
                if size.0.abs_diff(want.0) > 1 || size.1.abs_diff(want.1) > 1 {
                    return Err(StageError::Input(format!(
                        "{}: image is {}×{}, expected about {}×{} ({}×{} shrunk by {})",
                        pre.display(),
                        size.0,
                        size.1,
                        want.0,
                        want.1,
                        full.0,
                        full.1,
                        settings.downscale
                    )));
                }
                (absolute(&pre), size)
            } else {
                resampled.push(raw.name.as_str());
                let flat = raw.name.replace(['/', '\\'], "_");
                let base = flat
                    .rsplit_once('.')
                    .map_or(flat.as_str(), |(stem, _)| stem);
                // `001.png` and `001.jpg`, or `a/x.png` and `a_x.png`, flatten alike: each view
                // keeps a photo of its own.
                let mut rel = format!("images/{base}.png");
                let mut k = 1;
                while !written.insert(rel.clone()) {
                    rel = format!("images/{base}-{k}.png");
                    k += 1;
                }
                let dst = out.join(&rel);
                std::fs::create_dir_all(out.join("images"))
                    .map_err(|e| StageError::io(out.join("images"), e))?;
                let size =
                    write_downscaled(&raw.image, &dst, settings.downscale).map_err(input_error)?;
                (rel, size)
            };
        // Pixel-corner convention: scaling the image scales every intrinsic by the same ratio.
        let (sx, sy) = (
            f64::from(size.0) / f64::from(full.0),
            f64::from(size.1) / f64::from(full.1),
        );
        let cam = Camera {
            id: 0,
            width: size.0,
            height: size.1,
            fx: raw.intrinsics.fx * sx,
            fy: raw.intrinsics.fy * sy,
            cx: raw.intrinsics.cx * sx,
            cy: raw.intrinsics.cy * sy,
        };
        let id = match scene.cameras.iter().find(|c| {
            Camera {
                id: 0,
                ..(*c).clone()
            } == cam
        }) {
            Some(c) => c.id,
            None => {
                let id = scene.cameras.len() as u32 + 1;
                scene.cameras.push(Camera { id, ..cam });
                id
            }
        };
        let split = match (use_declared, raw.split) {
            (true, Some(s)) => s,
            // hold 0 (the option or a BAD-Gaussians marker): every view trains.
            _ if hold > 0 && (i as u32).is_multiple_of(hold) => Split::Test,
            _ => Split::Train,
        };
        scene.views.push(View {
            name: raw.name.clone(),
            image,
            camera: id,
            world_from_camera: raw.world_from_camera,
            split,
            lens: None,
            depth: raw.depth.as_deref().map(absolute),
        });
    }
    ctx.progress("check images", n, n);
    warn_resampled(
        dataset,
        settings.downscale,
        &resampled,
        data.views.len(),
        ctx,
    );
    scene.up = estimate_up(&scene.views);
    scene.bounds = data.bounds;
    let from_dataset = data.points.as_ref().is_some_and(|c| !c.is_empty());
    let cloud = match data.points.take().filter(|c| !c.is_empty()) {
        Some(c) => c,
        None => {
            ctx.warn(&format!(
                "{}: the dataset has no SfM points; starting from {FALLBACK_POINTS} random points {}",
                dataset.display(),
                if scene.bounds.is_some() {
                    "in the train views' frusta between the near and far bounds"
                } else {
                    "in a cube of side 2.6 around the origin (INRIA's synthetic-scene rule)"
                }
            ));
            fallback_points(&scene, FALLBACK_POINTS, 0)
        }
    };
    let points = cloud.len();
    cocog_formats::ply::write_points(&out.join("points.ply"), &cloud).map_err(input_error)?;
    scene.points = Some("points.ply".to_owned());
    scene.save(out)?;
    let test = scene.views_in(Split::Test).count();
    if !data.unposed.is_empty() && !use_declared && hold > 0 {
        warn_unposed(dataset, &data.unposed, &scene, hold, ctx);
    }
    if test == 0 {
        // Any hold > 0 makes view 0 a test view, so only these leave none.
        let why = if use_declared {
            "the dataset's own split puts every view in train"
        } else if settings.hold == Some(0) {
            "--hold 0 puts every view in train"
        } else {
            "its hold=0 marker means every view trains"
        };
        ctx.warn(&format!(
            "{}: the scene has no test views ({why}); train, render and export work, but \
             `cocog eval` has nothing held out to score: ingest with --hold 8 to keep every \
             8th view for testing, or score the training views with `cocog eval --split train`",
            dataset.display()
        ));
    }
    let summary = json!({
        "views": scene.views.len(),
        "train": scene.views.len() - test,
        "test": test,
        "split": if use_declared { "dataset".to_owned() } else { format!("hold={hold}") },
        "cameras": scene.cameras.len(),
        "points": points,
        "points_source": if from_dataset { "dataset" } else { "random fallback" },
        "downscale": settings.downscale,
    });
    Ok((scene, summary))
}
