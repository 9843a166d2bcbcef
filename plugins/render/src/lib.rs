//! cocog-render: renders a trained scene's views through the GPU engine.
//!
//! `render` writes one PNG per view (named after the view's image stem) and optionally its
//! depth as EXR; `eval-scene` renders a split and scores it against the scene's photos with
//! the same metrics as `eval`. [`SceneRenderer`] and [`split_cameras`] are the reusable part:
//! any camera, any resolution, sharp, with depth.

mod cameras;
mod eval_scene;
mod pose_file;
mod refocus;
mod render_stage;
mod renderer;

pub use cameras::{NamedCamera, parse_split, split_cameras, split_name};
pub use eval_scene::EvalScene;
pub use pose_file::cameras_from_file;
pub use refocus::{FocusChoice, LensScene, RefocusJob, distance_at};
pub use render_stage::Render;
pub use renderer::{SceneRenderer, load_gaussians};

/// The stages this crate provides.
pub fn stages() -> Vec<Box<dyn cocog_pipeline::Stage>> {
    vec![Box::new(Render), Box::new(EvalScene)]
}
