//! The `densify` stage: adds Deblurring-3DGS-style extra points to a scene's point cloud
//! (notes/method.md §8.1), for training to start from a denser, gap-free cloud.
//!
//! Options: `points` candidates to draw (default 200 000, the paper's cap), `seed`, and
//! `max-distance` (a candidate with no SfM point this close, in scene units, is dropped; 2.0 as
//! in the reference code). The output scene's `points.ply` holds the original points first,
//! then the new ones.

mod extra;

use cocog_formats::ply::{read_points, write_points};
use cocog_pipeline::{
    Context, OptionSpec, OutputKind, Scene, Stage, StageError, StageInfo, StageKind, StageRequest,
};
use serde_json::{Value, json};

/// The most candidate points `densify` draws (see the option's note).
pub const MAX_POINTS: usize = 100_000_000;

pub use extra::{Extra, SplitMix64, extra_points, robust_box};

pub struct Densify;

impl Stage for Densify {
    fn info(&self) -> StageInfo {
        StageInfo {
            name: "densify".to_owned(),
            kind: StageKind::Transform,
            output: OutputKind::Dir,
            needs_gaussians: false,
            description: "Add extra points in the point cloud's bounding box, coloured from their 4 nearest points".to_owned(),
            options: vec![
                // 15 bytes a point plus a k-d tree query each: 100 M is ~1.5 GB and minutes of
                // work, far past any scene 3DGS trains on, and refusing beyond it turns a
                // typo (an extra few zeros) into a message instead of an allocation abort.
                OptionSpec::int("points", 200_000, "candidate points to draw (those far from every SfM point are dropped)")
                    .between(0.0, MAX_POINTS as f64),
                OptionSpec::int("seed", 0, "random seed"),
                OptionSpec::float("max-distance", 2.0, "drop a candidate with no SfM point closer than this (scene units)"),
            ],
        }
    }

    fn run(&self, req: &StageRequest, ctx: &dyn Context) -> Result<Value, StageError> {
        let count = req.options.get_i64("points").unwrap_or(200_000);
        let count = usize::try_from(count)
            .ok()
            .filter(|&c| c <= MAX_POINTS)
            .ok_or_else(|| {
                StageError::Options(format!(
                    "densify: option 'points' must be from 0 to {MAX_POINTS}, got {count}"
                ))
            })?;
        let seed = req.options.get_i64("seed").unwrap_or(0) as u64;
        let max_distance = req.options.get_f64("max-distance").unwrap_or(2.0);
        if !(max_distance.is_finite() && max_distance > 0.0) {
            return Err(StageError::Options(format!(
                "densify: option 'max-distance' must be positive, got {max_distance}"
            )));
        }
        let mut scene = Scene::load(&req.input)?;
        let stored = scene.points.clone().ok_or_else(|| {
            StageError::Input(format!("{}: field `points`: the scene has no point cloud to densify (ingest a dataset with SfM points)", req.input.join("scene.json").display()))
        })?;
        let path = Scene::resolve(&req.input, &stored);
        let mut cloud = read_points(&path).map_err(|e| StageError::Input(e.to_string()))?;
        if cloud.is_empty() {
            return Err(StageError::Input(format!(
                "{}: the point cloud is empty",
                path.display()
            )));
        }
        let started = std::time::Instant::now();
        let extra = extra_points(&cloud, count, max_distance, seed, |done| {
            ctx.progress("densify", done as u64, count as u64);
            ctx.cancelled()
        })
        .ok_or(StageError::Cancelled)?;
        ctx.progress("densify", count as u64, count as u64);
        let (lo, hi) = robust_box(&cloud);
        let added = extra.points.len();
        cloud.positions.extend(&extra.points.positions);
        cloud.colors.extend(&extra.points.colors);
        scene.rebase(&req.input)?;
        write_points(&req.output.join("points.ply"), &cloud)
            .map_err(|e| StageError::Input(e.to_string()))?;
        scene.points = Some("points.ply".to_owned());
        scene.save(&req.output)?;
        ctx.info(&format!(
            "densify: added {added} points ({} dropped) in {:.2} s",
            extra.dropped,
            started.elapsed().as_secs_f64()
        ));
        Ok(
            json!({"added": added, "dropped": extra.dropped, "total": cloud.len(), "box_min": lo, "box_max": hi}),
        )
    }
}

/// The densify stage, for the CLI to register.
pub fn stages() -> Vec<Box<dyn Stage>> {
    vec![Box::new(Densify)]
}
