//! An example out-of-tree-style cocog plugin with one real stage, `recenter`.
//!
//! It moves the scene so the mean camera centre is at the origin and scales it so the
//! farthest camera is `radius` away. 3DGS learning rates are tuned for scenes of about
//! unit extent, so datasets with arbitrary units (metres, COLMAP's gauge) train better
//! normalised. Everything measured in scene units follows: poses, bounds, focus distances,
//! the CoC aperture scale, the point cloud and any trained Gaussians.
//!
//! Build it with `cargo build -p cocog-plugin-recenter` and load it with
//! `cocog --plugin-path target/debug stage recenter SCENE -o OUT`.

mod transform;

use cocog_pipeline::{
    Context, OptionSpec, OutputKind, Scene, Stage, StageError, StageInfo, StageKind, StageRequest,
};
use serde_json::{Value, json};

pub use transform::Similarity;

pub struct Recenter;

impl Stage for Recenter {
    fn info(&self) -> StageInfo {
        StageInfo {
            name: "recenter".to_owned(),
            kind: StageKind::Transform,
            output: OutputKind::Dir,
            needs_gaussians: false,
            description: "Move the mean camera centre to the origin and scale the farthest \
                          camera to `radius`"
                .to_owned(),
            options: vec![OptionSpec::float(
                "radius",
                1.0,
                "distance of the farthest camera centre from the origin after scaling",
            )],
        }
    }

    fn run(&self, req: &StageRequest, ctx: &dyn Context) -> Result<Value, StageError> {
        let radius = req.options.get_f64("radius").unwrap_or(1.0);
        if !(radius.is_finite() && radius > 0.0) {
            return Err(StageError::Options(format!(
                "recenter: option 'radius' must be a positive number, got {radius}"
            )));
        }
        let mut scene = Scene::load(&req.input)?;
        let sim = Similarity::normalising(&scene, radius).ok_or_else(|| {
            StageError::Input(format!(
                "{}/scene.json: field `views`: need at least two distinct camera centres to \
                 choose a scale",
                req.input.display()
            ))
        })?;
        ctx.info(&format!(
            "recenter: translate by {:?}, scale by {:.6}",
            sim.translation, sim.scale
        ));
        sim.apply_to_scene(&mut scene);
        transform::carry_files(&mut scene, &req.input, &req.output, &sim, ctx)?;
        scene.save(&req.output)?;
        Ok(json!({
            "scale": sim.scale,
            "translation": sim.translation,
            "views": scene.views.len(),
        }))
    }
}

fn stages() -> Vec<Box<dyn Stage>> {
    vec![Box::new(Recenter)]
}

cocog_pipeline::export_plugin!(
    name: "recenter",
    version: env!("CARGO_PKG_VERSION"),
    stages: stages
);
