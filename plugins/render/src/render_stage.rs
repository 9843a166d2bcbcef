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

use crate::{SceneRenderer, load_gaussians, parse_split, split_cameras};

pub struct Render;

/// Below this alpha a pixel saw no Gaussian and its depth is written as 0.
const MIN_ALPHA_FOR_DEPTH: f32 = 1e-6;

/// What to render, shared with `eval-scene`.
pub(crate) struct RenderJob {
    pub split: Option<Split>,
    pub downscale: u32,
    pub background: [f32; 3],
    pub depth: bool,
}

pub(crate) fn split_option() -> OptionSpec {
    OptionSpec::string("split", "test", "which views: test, train or all")
}

pub(crate) fn downscale_option() -> OptionSpec {
    OptionSpec::int(
        "downscale",
        1,
        "render at the views' size divided by N (match the training --downscale)",
    )
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

fn parse_background(text: &str) -> Result<[f32; 3], StageError> {
    let bad = || {
        StageError::Options(format!(
            "option 'background': expected three numbers in 0..1 like \"0,0,0\", got {text:?}"
        ))
    };
    let parts: Vec<f32> = text
        .split(',')
        .map(|s| s.trim().parse::<f32>().map_err(|_| bad()))
        .collect::<Result<_, _>>()?;
    match parts[..] {
        [r, g, b] if parts.iter().all(|v| (0.0..=1.0).contains(v)) => Ok([r, g, b]),
        _ => Err(bad()),
    }
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
    let cameras = split_cameras(&scene, scene_dir, job.split, job.downscale)?;
    let gaussians = load_gaussians(&scene, scene_dir)?;
    let gpu = GpuContext::new().map_err(StageError::other)?;
    let mut renderer =
        SceneRenderer::new(&gpu, &gaussians, job.background).map_err(StageError::other)?;
    if job.depth {
        let dir = out.join("depth");
        std::fs::create_dir_all(&dir).map_err(|e| StageError::io(&dir, e))?;
    }
    let start = Instant::now();
    let total = cameras.len() as u64;
    for (i, view) in cameras.iter().enumerate() {
        ctx.check_cancelled()?;
        ctx.progress("render", i as u64, total);
        let img = renderer.render(&view.camera).map_err(StageError::other)?;
        let png = out.join(format!("{}.png", view.stem()));
        to_rgb8(&img)
            .save(&png)
            .map_err(|e| StageError::io(&png, std::io::Error::other(e)))?;
        if job.depth {
            let exr = out.join("depth").join(format!("{}.exr", view.stem()));
            write_exr(&exr, &depth_map(&img)).map_err(StageError::other)?;
        }
    }
    ctx.progress("render", total, total);
    let (w, h) = (cameras[0].camera.width, cameras[0].camera.height);
    Ok(json!({
        "split": job.split.map_or("all", crate::split_name),
        "downscale": job.downscale,
        "views": cameras.len(),
        "width": w,
        "height": h,
        "gaussians": gaussians.len(),
        "seconds": start.elapsed().as_secs_f64(),
        "adapter": gpu.adapter_name(),
    }))
}

impl Stage for Render {
    fn info(&self) -> StageInfo {
        StageInfo {
            name: "render".into(),
            kind: StageKind::Render,
            output: OutputKind::Dir,
            description: "Render a trained scene's views to PNG (<view stem>.png), optionally \
                          with depth (depth/<stem>.exr: expected depth ÷ alpha, 0 where empty)"
                .into(),
            options: vec![
                split_option(),
                downscale_option(),
                OptionSpec::bool("depth", false, "also write depth maps as EXR"),
                OptionSpec::string("background", "0,0,0", "background colour r,g,b in 0..1"),
                OptionSpec::optional(
                    "focus_distance",
                    OptionKind::Float,
                    "refocus: plane in focus (needs a CoCoGaussian model; not available yet)",
                ),
                OptionSpec::optional(
                    "aperture",
                    OptionKind::Float,
                    "refocus: aperture scale K (needs a CoCoGaussian model; not available yet)",
                ),
            ],
        }
    }

    fn run(&self, req: &StageRequest, ctx: &dyn Context) -> Result<Value, StageError> {
        let o = &req.options;
        if o.get_f64("focus_distance").is_some() || o.get_f64("aperture").is_some() {
            return Err(StageError::Options(
                "refocused rendering (--focus-distance/--aperture) needs a CoCoGaussian model, \
                 which `train --method cocog` does not produce yet; render sharp without them"
                    .into(),
            ));
        }
        let job = RenderJob {
            split: parse_split(o.get_str("split").unwrap_or("test"))?,
            downscale: downscale(req, "render")?,
            background: parse_background(o.get_str("background").unwrap_or("0,0,0"))?,
            depth: o.get_bool("depth").unwrap_or(false),
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
