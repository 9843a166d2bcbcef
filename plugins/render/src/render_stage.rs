//! The `render` stage: a trained scene's views to PNG (and depth to EXR).

use std::path::Path;
use std::time::Instant;

use cocog_engine::{GpuContext, RenderedImage};
use cocog_formats::exr_map::{FloatMap, write_exr};
use cocog_pipeline::{
    Context, OptionKind, OptionSpec, OutputKind, Scene, Split, Stage, StageError, StageInfo,
    StageKind, StageRequest,
};
use serde_json::{Value, json};

use crate::refocus::{FocusChoice, LensScene, RefocusJob};
use crate::{NamedCamera, SceneRenderer, load_gaussians, parse_split, split_cameras};
use cocog_engine::nn::CompositeMode;

pub struct Render;

/// Below this alpha a pixel saw no Gaussian and its depth is written as 0.
const MIN_ALPHA_FOR_DEPTH: f32 = 1e-6;

/// What to render, shared with `eval-scene`.
pub(crate) struct RenderJob {
    pub split: Option<Split>,
    pub downscale: u32,
    pub background: [f32; 3],
    pub depth: bool,
    /// Only these views (names, render names or unshared stems), in this order; all of the
    /// split when empty.
    pub views: Vec<String>,
    /// Depth of field through the scene's lens model; sharp when `None`.
    pub refocus: Option<RefocusJob>,
    /// A focus pull: these focus distances over the one view, as `frame-NNN.png`.
    pub sweep: Vec<f64>,
    /// New cameras from this JSON file instead of the scene's views.
    pub camera_file: Option<std::path::PathBuf>,
}

pub(crate) fn split_option() -> OptionSpec {
    OptionSpec::string("split", "test", "which views: test, train or all")
        .one_of(&["test", "train", "all"])
}

pub(crate) fn downscale_option() -> OptionSpec {
    OptionSpec::int(
        "downscale",
        1,
        "render at the views' size divided by N (match the training --downscale)",
    )
    .between(1.0, 64.0)
}

pub(crate) fn downscale(req: &StageRequest, stage: &str) -> Result<u32, StageError> {
    let d = req.options.get_i64("downscale").unwrap_or(1);
    u32::try_from(d)
        .ok()
        .filter(|d| (1..=64).contains(d))
        .ok_or_else(|| {
            StageError::Options(format!(
                "stage '{stage}' option 'downscale' must be in 1..=64, got {d}"
            ))
        })
}

/// What the scene was trained over; black when unrecorded (a bad scene.json is reported by
/// the render itself, with its path).
pub(crate) fn trained_background(scene_dir: &Path) -> [f32; 3] {
    cocog_pipeline::Scene::load(scene_dir)
        .ok()
        .and_then(|s| s.trained_background())
        .unwrap_or([0.0; 3])
}

fn parse_background(text: &str) -> Result<[f32; 3], StageError> {
    cocog_pipeline::parse_colour("background", text)
}

/// 8-bit RGB, clamped and rounded: the values are trained as stored, so no transfer curve.
fn to_rgb8(img: &RenderedImage) -> image::RgbImage {
    let bytes = img
        .color
        .iter()
        .flatten()
        .map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8)
        .collect();
    image::RgbImage::from_raw(img.width, img.height, bytes).expect("one rgb triple per pixel")
}

/// Expected depth along the optical axis where something was seen, else 0.
fn depth_map(img: &RenderedImage) -> FloatMap {
    let data = img
        .depth
        .iter()
        .zip(&img.alpha)
        .map(|(&d, &a)| if a > MIN_ALPHA_FOR_DEPTH { d / a } else { 0.0 })
        .collect();
    FloatMap {
        width: img.width as usize,
        height: img.height as usize,
        data,
    }
}

/// Renders the job's views of the scene at `scene_dir` into `out` as `<stem>.png` (and
/// `depth/<stem>.exr`); returns a summary.
pub(crate) fn render_views(
    scene_dir: &Path,
    job: &RenderJob,
    out: &Path,
    ctx: &dyn Context,
) -> Result<Value, StageError> {
    let mut scene = Scene::load(scene_dir)?;
    scene.rebase(scene_dir)?;
    let cameras = match &job.camera_file {
        Some(path) => crate::cameras_from_file(path, &scene, scene_dir, job.downscale)?,
        None => select(
            split_cameras(&scene, scene_dir, job.split, job.downscale)?,
            &job.views,
            job.split,
        )?,
    };
    if !job.sweep.is_empty() && cameras.len() != 1 {
        return Err(StageError::Options(format!(
            "option 'focus_sweep' pulls focus over one view; the camera file has {}",
            cameras.len()
        )));
    }
    let gaussians = load_gaussians(&scene, scene_dir)?;
    let lens_scene = match &job.refocus {
        Some(_) => Some(LensScene::load(&scene, scene_dir)?),
        None => None,
    };
    // Everything a request can get wrong is checked before the GPU starts.
    if let (Some(l), Some(r)) = (&lens_scene, &job.refocus) {
        match &r.focus {
            FocusChoice::FromView(name) => {
                l.train_index(name)?;
            }
            FocusChoice::At(x, y) => {
                if let Some(c) = cameras
                    .iter()
                    .find(|c| *x >= c.camera.width || *y >= c.camera.height)
                {
                    return Err(StageError::Options(format!(
                        "option 'focus_at': pixel ({x}, {y}) is outside view {} ({}×{})",
                        c.name, c.camera.width, c.camera.height
                    )));
                }
            }
            _ => {}
        }
    }
    let gpu = GpuContext::new().map_err(StageError::other)?;
    let mut refocus = match &lens_scene {
        Some(l) => Some(l.renderer(&gpu, &gaussians)?),
        None => None,
    };
    let mut renderer =
        SceneRenderer::new(&gpu, &gaussians, job.background).map_err(StageError::other)?;
    if job.depth {
        let dir = out.join("depth");
        std::fs::create_dir_all(&dir).map_err(|e| StageError::io(&dir, e))?;
    }
    let start = Instant::now();
    let mut lenses = Vec::new();
    // A sweep renders its one view once per focus distance, into numbered frames.
    let frames: Vec<(String, &NamedCamera, Option<RefocusJob>)> = if job.sweep.is_empty() {
        cameras
            .iter()
            .map(|v| (v.output.clone(), v, job.refocus.clone()))
            .collect()
    } else {
        let base = job.refocus.clone().ok_or_else(|| {
            StageError::Options("option 'focus_sweep' is a refocus: it needs a lens".into())
        })?;
        job.sweep
            .iter()
            .enumerate()
            .map(|(i, d)| {
                let rj = RefocusJob {
                    focus: FocusChoice::Distance(*d),
                    ..base.clone()
                };
                (format!("frame-{i:03}"), &cameras[0], Some(rj))
            })
            .collect()
    };
    let total = frames.len() as u64;
    for (i, (stem, view, refocus_job)) in frames.iter().enumerate() {
        ctx.check_cancelled()?;
        ctx.progress("render", i as u64, total);
        let img = match (&lens_scene, refocus.as_mut(), refocus_job) {
            (Some(l), Some(r), Some(rj)) => {
                let (img, lens) = l.render(r, view, job.background, rj)?;
                lenses.push(json!({
                    "view": view.name,
                    "image": format!("{stem}.png"),
                    "focus_distance": lens.map(|l| l.focus_distance),
                    "aperture": lens.map(|l| l.aperture),
                }));
                img
            }
            _ => renderer.render(&view.camera).map_err(StageError::other)?,
        };
        let png = out.join(format!("{stem}.png"));
        to_rgb8(&img)
            .save(&png)
            .map_err(|e| StageError::io(&png, std::io::Error::other(e)))?;
        if job.depth {
            let exr = out.join("depth").join(format!("{stem}.exr"));
            write_exr(&exr, &depth_map(&img)).map_err(StageError::other)?;
        }
    }
    ctx.progress("render", total, total);
    let (w, h) = (cameras[0].camera.width, cameras[0].camera.height);
    Ok(json!({
        "split": job.split.map_or("all", crate::split_name),
        "downscale": job.downscale,
        "views": cameras.len(),
        "frames": frames.len(),
        "width": w,
        "height": h,
        "gaussians": gaussians.len(),
        "seconds": start.elapsed().as_secs_f64(),
        "adapter": gpu.adapter_name(),
        "lenses": (!lenses.is_empty()).then_some(lenses),
    }))
}

/// The cameras named in `wanted` (names, stems or render names), in that order; all when it is
/// empty. `split` is the split they were chosen from (None: all views), for the error's hint.
fn select(
    cameras: Vec<NamedCamera>,
    wanted: &[String],
    split: Option<Split>,
) -> Result<Vec<NamedCamera>, StageError> {
    if wanted.is_empty() {
        return Ok(cameras);
    }
    wanted
        .iter()
        .map(|w| {
            // The full name, then the render name (unique), then the stem, which views in
            // different folders may share: `r_0` is then ambiguous, `test_r_0` is not.
            let by_stem: Vec<&NamedCamera> = cameras.iter().filter(|c| &c.stem() == w).collect();
            if by_stem.len() > 1 && !cameras.iter().any(|c| &c.name == w || &c.output == w) {
                let names: Vec<&str> = by_stem.iter().map(|c| c.name.as_str()).collect();
                let outputs: Vec<&str> = by_stem.iter().map(|c| c.output.as_str()).collect();
                return Err(StageError::Options(format!(
                    "option 'views': {w:?} names more than one view ({}); give the full name \
                     or the render name ({})",
                    names.join(", "),
                    outputs.join(" or ")
                )));
            }
            cameras
                .iter()
                .find(|c| &c.name == w)
                .or_else(|| cameras.iter().find(|c| &c.output == w))
                .or(by_stem.first().copied())
                .cloned()
                .ok_or_else(|| {
                    let names: Vec<&str> = cameras.iter().map(|c| c.name.as_str()).collect();
                    let hint = match split {
                        Some(s) => {
                            let other = match s {
                                Split::Train => Split::Test,
                                Split::Test => Split::Train,
                            };
                            format!(
                                "; --split {} or --split all chooses among the others",
                                crate::split_name(other)
                            )
                        }
                        None => String::new(),
                    };
                    let which = split.map_or("the scene", |s| crate::split_name(s));
                    StageError::Options(format!(
                        "option 'views': no view named {w:?} in {which} (views: {}){hint}",
                        names.join(", ")
                    ))
                })
        })
        .collect()
}

/// Focus distances NEAR..FAR over FRAMES frames, even in 1/distance (as a focus ring turns).
pub fn sweep_distances(text: &str) -> Result<Vec<f64>, StageError> {
    let bad = |why: &str| {
        StageError::Options(format!(
            "option 'focus_sweep': expected NEAR:FAR:FRAMES like 0.5:3:24 (distances in scene \
             units, 2 to 1000 frames), got {text:?}: {why}"
        ))
    };
    let parts: Vec<&str> = text.split(':').collect();
    let [near, far, frames] = parts[..] else {
        return Err(bad("three fields"));
    };
    let num = |s: &str| {
        s.trim()
            .parse::<f64>()
            .ok()
            .filter(|v| v.is_finite() && *v > 0.0)
    };
    let (near, far) = (
        num(near).ok_or_else(|| bad("NEAR must be a positive distance"))?,
        num(far).ok_or_else(|| bad("FAR must be a positive distance"))?,
    );
    let frames: usize = frames
        .trim()
        .parse()
        .ok()
        .filter(|f| (2..=1000).contains(f))
        .ok_or_else(|| bad("FRAMES must be a count from 2 to 1000"))?;
    Ok((0..frames)
        .map(|i| {
            let t = i as f64 / (frames - 1) as f64;
            1.0 / ((1.0 - t) / near + t / far)
        })
        .collect())
}

/// `job` as a focus pull: one view, the sweep's distances, the other lens options kept.
fn sweep_job(mut job: RenderJob, text: &str) -> Result<RenderJob, StageError> {
    if job.views.len() != 1 && job.camera_file.is_none() {
        return Err(StageError::Options(
            "option 'focus_sweep' pulls focus over one view: name it with option 'views' \
             (--views NAME), or give one new camera with option 'camera'"
                .into(),
        ));
    }
    job.sweep = sweep_distances(text)?;
    job.refocus = Some(RefocusJob {
        focus: FocusChoice::Distance(job.sweep[0]),
        aperture: job.refocus.as_ref().map_or(1.0, |r| r.aperture),
        composite: job.refocus.as_ref().and_then(|r| r.composite),
    });
    Ok(job)
}

/// The refocus options, checked; `None` when none is given (a sharp render).
fn refocus_job(req: &StageRequest) -> Result<Option<RefocusJob>, StageError> {
    let o = &req.options;
    let focus = o.get_str("focus_distance");
    let at = o.get_str("focus_at");
    let photographed = o.get_bool("as_photographed").unwrap_or(false);
    let sweep = o.get_str("focus_sweep").is_some();
    let aperture = o.get_f64("aperture");
    let given = [focus.is_some(), at.is_some(), photographed, sweep]
        .iter()
        .filter(|b| **b)
        .count();
    if given > 1 {
        return Err(StageError::Options(
            "choose one of focus_distance, focus_at, as_photographed and focus_sweep".into(),
        ));
    }
    if given == 0 {
        if aperture.is_some() {
            return Err(StageError::Options(
                "option 'aperture' needs a focus: focus_distance, focus_at or as_photographed"
                    .into(),
            ));
        }
        return Ok(None);
    }
    let aperture = aperture.unwrap_or(1.0);
    if !(aperture.is_finite() && aperture >= 0.0) {
        return Err(StageError::Options(format!(
            "option 'aperture' must be 0 or more (1 = as photographed, 0 = sharp), got {aperture}"
        )));
    }
    let focus = if photographed {
        FocusChoice::AsPhotographed
    } else if sweep {
        // Each frame replaces it (sweep_job).
        FocusChoice::Distance(1.0)
    } else if let Some(f) = focus {
        match f.strip_prefix("from:") {
            Some(view) => FocusChoice::FromView(view.to_owned()),
            None => match f.parse::<f64>() {
                Ok(d) if d.is_finite() && d > 0.0 => FocusChoice::Distance(d),
                _ => {
                    return Err(StageError::Options(format!(
                        "option 'focus_distance': expected a positive distance in scene units \
                         or from:VIEW, got {f:?}"
                    )));
                }
            },
        }
    } else {
        let text = at.unwrap_or_default();
        let bad = || {
            StageError::Options(format!(
                "option 'focus_at': expected a pixel X,Y like \"200,150\", got {text:?}"
            ))
        };
        let (x, y) = text.split_once(',').ok_or_else(bad)?;
        FocusChoice::At(
            x.trim().parse().map_err(|_| bad())?,
            y.trim().parse().map_err(|_| bad())?,
        )
    };
    let composite = match o.get_str("composite") {
        None => None,
        Some("learned") => Some(CompositeMode::Learned),
        Some("mean") => Some(CompositeMode::Uniform),
        Some(other) => {
            return Err(StageError::Options(format!(
                "option 'composite': expected learned or mean, got {other:?}"
            )));
        }
    };
    Ok(Some(RefocusJob {
        focus,
        aperture,
        composite,
    }))
}

impl Stage for Render {
    fn info(&self) -> StageInfo {
        StageInfo {
            name: "render".into(),
            kind: StageKind::Render,
            output: OutputKind::Dir,
            needs_gaussians: true,
            description: "Render a trained scene's views to PNG (<view stem>.png), optionally \
                          with depth (depth/<stem>.exr: expected depth ÷ alpha, 0 where empty)"
                .into(),
            options: vec![
                split_option(),
                downscale_option(),
                OptionSpec::bool("depth", false, "also write depth maps as EXR"),
                OptionSpec::optional(
                    "background",
                    OptionKind::String,
                    "background colour: black, white or r,g,b in 0..1 (default: the one the \
                     scene was trained over, black for scenes from before it was recorded)",
                ),
                OptionSpec::optional(
                    "views",
                    OptionKind::String,
                    "only these views, comma-separated names, render names (test_r_0) or stems no \
                     other view shares (default: the whole split)",
                ),
                OptionSpec::optional(
                    "camera",
                    OptionKind::Path,
                    "render new cameras instead of the scene's views: a JSON file with one \
                     {\"world_from_camera\": 4×4 rows, \"camera\": scene camera id, \"name\"} \
                     or a list of them (scene.json's convention; camera defaults to the first \
                     training view's)",
                ),
                OptionSpec::optional(
                    "focus_distance",
                    OptionKind::String,
                    "refocus (cocog scenes): distance in focus from the camera centre, in scene \
                     units, or from:VIEW for a training photo's learned focus",
                ),
                OptionSpec::optional(
                    "focus_at",
                    OptionKind::String,
                    "refocus: focus on the surface under pixel X,Y of each rendered view",
                ),
                OptionSpec::optional(
                    "as_photographed",
                    OptionKind::Bool,
                    "refocus: each training view with its own learned focus and aperture (views \
                     without one render sharp)",
                ),
                OptionSpec::optional(
                    "aperture",
                    OptionKind::Float,
                    "refocus: multiplies the learned aperture (1 = as photographed, 0 = sharp, \
                     2 = twice the blur)",
                ),
                OptionSpec::optional(
                    "composite",
                    OptionKind::String,
                    "refocus: blend the CoC renders with the learned compositor F (learned) or \
                     take their mean (mean); default: F when training reached its start, else \
                     the mean",
                ),
                OptionSpec::optional(
                    "focus_sweep",
                    OptionKind::String,
                    "a focus pull over one view (option views): NEAR:FAR:FRAMES, focus distances \
                     even in 1/distance, written as frame-NNN.png",
                ),
            ],
        }
    }

    fn run(&self, req: &StageRequest, ctx: &dyn Context) -> Result<Value, StageError> {
        let o = &req.options;
        let views = o
            .get_str("views")
            .map(|v| {
                v.split(',')
                    .map(|s| s.trim().to_owned())
                    .filter(|s| !s.is_empty())
                    .collect()
            })
            .unwrap_or_default();
        let job = RenderJob {
            split: parse_split(o.get_str("split").unwrap_or("test"))?,
            downscale: downscale(req, "render")?,
            background: match o.get_str("background") {
                Some(text) => parse_background(text)?,
                None => trained_background(&req.input),
            },
            depth: o.get_bool("depth").unwrap_or(false),
            views,
            refocus: refocus_job(req)?,
            sweep: Vec::new(),
            camera_file: o.get_path("camera"),
        };
        if job.camera_file.is_some() && !job.views.is_empty() {
            return Err(StageError::Options(
                "choose either option 'views' (the scene's views) or 'camera' (new ones)".into(),
            ));
        }
        let job = match o.get_str("focus_sweep") {
            None => job,
            Some(text) => sweep_job(job, text)?,
        };
        let summary = render_views(&req.input, &job, &req.output, ctx)?;
        let path = req.output.join("render.json");
        let text = serde_json::to_string_pretty(&summary).map_err(StageError::other)?;
        std::fs::write(&path, text).map_err(|e| StageError::io(&path, e))?;
        Ok(summary)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn backgrounds_parse_or_say_what_is_expected() {
        assert_eq!(parse_background("1, 0.5,0").unwrap(), [1.0, 0.5, 0.0]);
        for bad in ["", "1,1", "1,1,2", "a,b,c", "0,0,0,0"] {
            let e = parse_background(bad).unwrap_err().to_string();
            assert!(e.contains("three numbers"), "{bad}: {e}");
        }
    }
}
