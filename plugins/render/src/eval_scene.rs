//! The `eval-scene` stage: render a split of a trained scene and score it against its photos.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use cocog_eval::{CtxObserver, eval_options, metric_options, stage_error};
use cocog_formats::images::write_downscaled_over;
use cocog_pipeline::{Context, OutputKind, Stage, StageError, StageInfo, StageKind, StageRequest};
use serde_json::{Value, json};

use crate::render_stage::{
    RenderJob, downscale, downscale_option, render_views, split_option, trained_background,
};
use crate::{parse_split, split_cameras};

pub struct EvalScene;

/// The split's photos at the render size, named by view stem so they pair with the renders;
/// returns each stem's original photo.
fn ground_truth(
    scene_dir: &Path,
    job: &RenderJob,
    out: &Path,
    ctx: &dyn Context,
) -> Result<BTreeMap<String, PathBuf>, StageError> {
    let mut scene = cocog_pipeline::Scene::load(scene_dir)?;
    scene.rebase(scene_dir)?;
    let views = split_cameras(&scene, scene_dir, job.split, job.downscale)?;
    for (i, view) in views.iter().enumerate() {
        let stem = &view.output;
        ctx.check_cancelled()?;
        ctx.progress("ground truth", i as u64, views.len() as u64);
        // write_downscaled always encodes PNG (lossless, even for a JPEG photo at factor 1).
        let dst = out.join(format!("{stem}.png"));
        let (w, h) = write_downscaled_over(&view.image, &dst, job.downscale, Some(job.background))
            .map_err(|e| StageError::Input(format!("view {:?}: {e}", view.name)))?;
        if (w, h) != (view.camera.width, view.camera.height) {
            return Err(StageError::Input(format!(
                "{}: the photo is {w}×{h} at downscale {}, its camera {}×{}",
                view.image.display(),
                job.downscale,
                view.camera.width,
                view.camera.height
            )));
        }
    }
    Ok(views.into_iter().map(|v| (v.output, v.image)).collect())
}

/// The report names the scratch folders, which are gone once the stage returns: point at the
/// scene and its photos instead.
fn replace_scratch_paths(report: &mut Value, scene_dir: &Path, photos: &BTreeMap<String, PathBuf>) {
    let Some(map) = report.as_object_mut() else {
        return;
    };
    map.remove("pred_dir");
    map.remove("gt_dir");
    map.insert("scene".into(), json!(scene_dir));
    let images = map.get_mut("images").and_then(Value::as_array_mut);
    for image in images.into_iter().flatten() {
        if let Some(entry) = image.as_object_mut() {
            entry.remove("pred");
            let name = entry
                .get("name")
                .and_then(Value::as_str)
                .unwrap_or_default();
            let photo = photos.get(name).map(|p| json!(p));
            entry.insert("gt".into(), photo.unwrap_or(Value::Null));
        }
    }
}

impl Stage for EvalScene {
    fn info(&self) -> StageInfo {
        StageInfo {
            name: "eval-scene".into(),
            kind: StageKind::Eval,
            output: OutputKind::File,
            needs_gaussians: true,
            description: "Render a trained scene's views (default: the test split) and score \
                          them against its photos like `eval`; writes metrics.json"
                .into(),
            options: [split_option(), downscale_option()]
                .into_iter()
                .chain(metric_options())
                .collect(),
        }
    }

    fn run(&self, req: &StageRequest, ctx: &dyn Context) -> Result<Value, StageError> {
        let split_name = req.options.get_str("split").unwrap_or("test").to_owned();
        let job = RenderJob {
            split: parse_split(&split_name)?,
            downscale: downscale(req, "eval-scene")?,
            // Over the training colour, with the photos' alpha composited over it too.
            background: trained_background(&req.input),
            depth: false,
            views: Vec::new(),
            refocus: None,
            sweep: Vec::new(),
            camera_file: None,
        };
        let opts = eval_options(req)?;
        // Beside the output, so the renders sit on the same disk and vanish with the stage
        // (or, after a kill, with the next run's stale temporaries).
        let work = cocog_pipeline::atomic::scratch_beside(&req.output)
            .map_err(|e| StageError::io(&req.output, e))?;
        let (pred, gt) = (work.path().join("renders"), work.path().join("gt"));
        for dir in [&pred, &gt] {
            std::fs::create_dir(dir).map_err(|e| StageError::io(dir, e))?;
        }
        let rendered = render_views(&req.input, &job, &pred, ctx)?;
        let photos = ground_truth(&req.input, &job, &gt, ctx)?;
        let mut json = cocog_metrics_eval(&pred, &gt, &opts, ctx).map_err(|e| match e {
            // The renders are scratch files: name the view's photo and the size it was scored at.
            cocog_eval::MetricsError::TooSmall {
                path,
                width,
                height,
                metric,
                min,
            } => {
                let stem = path
                    .file_stem()
                    .and_then(|s| s.to_str())
                    .unwrap_or_default();
                let photo = photos.get(stem).map_or(path.clone(), PathBuf::clone);
                StageError::Input(format!(
                    "{}: scored at {width}x{height} (downscale {}); {metric} needs at least \
                     {min}x{min}: use a smaller --downscale, or --lpips off where LPIPS is \
                     the one",
                    photo.display(),
                    job.downscale
                ))
            }
            e => stage_error(e),
        })?;
        replace_scratch_paths(&mut json, &req.input, &photos);
        if let Some(map) = json.as_object_mut() {
            map.insert("split".into(), json!(split_name));
            map.insert("downscale".into(), json!(job.downscale));
            map.insert("views".into(), rendered["views"].clone());
            map.insert("gaussians".into(), rendered["gaussians"].clone());
        }
        cocog_eval::write_json_atomic(&req.output, &json).map_err(stage_error)?;
        Ok(json)
    }
}

fn cocog_metrics_eval(
    pred: &Path,
    gt: &Path,
    opts: &cocog_eval::EvalOptions,
    ctx: &dyn Context,
) -> Result<Value, cocog_eval::MetricsError> {
    let report = cocog_eval::evaluate_dirs(pred, gt, opts, &CtxObserver(ctx))?;
    if let Some(note) = &report.lpips.note
        && opts.lpips != cocog_eval::LpipsMode::Off
    {
        ctx.warn(note);
    }
    Ok(report.to_json())
}
