//! The `prune` stage (notes/method.md §8.2): removes Gaussians whose opacity is below a
//! threshold that relaxes with height, as Deblurring 3DGS does.
//!
//! With z the world z of a mean, w = 1 + (range − 1)·(z − z_min)/(z_max − z_min) ∈ [1, range],
//! a Gaussian is pruned when sigmoid(opacity) < threshold / w. The reference uses the world
//! z axis (not camera depth), and so do we.

mod depth_prune;

use cocog_formats::ply::{read_splats, write_splats};
use cocog_pipeline::{
    Context, OptionSpec, OutputKind, Scene, Stage, StageError, StageInfo, StageKind, StageRequest,
};
use serde_json::{Value, json};

pub use depth_prune::keep_mask;

pub struct Prune;

impl Stage for Prune {
    fn info(&self) -> StageInfo {
        StageInfo {
            name: "prune".to_owned(),
            kind: StageKind::Transform,
            output: OutputKind::Dir,
            needs_gaussians: true,
            description:
                "Remove nearly transparent Gaussians, with a threshold that relaxes with world z"
                    .to_owned(),
            options: vec![
                OptionSpec::float(
                    "threshold",
                    0.005,
                    "opacity below which a Gaussian at the lowest z is removed",
                ),
                OptionSpec::float(
                    "range",
                    3.0,
                    "the threshold is divided by up to this factor at the highest z",
                ),
            ],
        }
    }

    fn run(&self, req: &StageRequest, ctx: &dyn Context) -> Result<Value, StageError> {
        let threshold = req.options.get_f64("threshold").unwrap_or(0.005);
        let range = req.options.get_f64("range").unwrap_or(3.0);
        if !(threshold.is_finite() && (0.0..1.0).contains(&threshold)) {
            return Err(StageError::Options(format!(
                "prune: option 'threshold' must be in [0, 1), got {threshold}"
            )));
        }
        if !(range.is_finite() && range >= 1.0) {
            return Err(StageError::Options(format!(
                "prune: option 'range' must be ≥ 1, got {range}"
            )));
        }
        let mut scene = Scene::load(&req.input)?;
        let stored = scene.gaussians.clone().ok_or_else(|| {
            StageError::Input(format!("{}: field `gaussians`: the scene has no trained Gaussians to prune (run train first)", req.input.join("scene.json").display()))
        })?;
        let mut splats = read_splats(&Scene::resolve(&req.input, &stored))
            .map_err(|e| StageError::Input(e.to_string()))?;
        let before = splats.len();
        let keep = keep_mask(&splats, threshold, range);
        splats.retain(&keep);
        // An empty scene renders black everywhere: refuse it rather than hand it on.
        if splats.is_empty() {
            return Err(if before == 0 {
                StageError::Input(format!(
                    "{}: holds no Gaussians, so there is nothing to prune",
                    Scene::resolve(&req.input, &stored).display()
                ))
            } else {
                StageError::Options(format!(
                    "prune: threshold {threshold} with range {range} would remove all \
                     {before} Gaussians; choose a smaller threshold"
                ))
            });
        }
        ctx.info(&format!(
            "prune: kept {} of {before} Gaussians",
            splats.len()
        ));
        scene.rebase(&req.input)?;
        write_splats(&req.output.join("gaussians.ply"), &splats, None)
            .map_err(|e| StageError::Input(e.to_string()))?;
        scene.gaussians = Some("gaussians.ply".to_owned());
        scene.save(&req.output)?;
        Ok(json!({"before": before, "after": splats.len(), "removed": before - splats.len()}))
    }
}

/// The prune stage, for the CLI to register.
pub fn stages() -> Vec<Box<dyn Stage>> {
    vec![Box::new(Prune)]
}
