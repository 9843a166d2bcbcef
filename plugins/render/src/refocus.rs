//! Refocused renders of a CoCoGaussian scene: its lens model (`lens-model.safetensors`) with
//! a chosen focus distance and aperture, or each training photo's own lens.

use std::path::Path;

use cocog_engine::coc::{CocConfig, CocVariant, Frame, Lens, Refocus};
use cocog_engine::nn::CompositeMode;
use cocog_engine::{Camera, GpuContext, RenderedImage};
use cocog_formats::lens_model::LensModel;
use cocog_pipeline::{Scene, Split, StageError};

use crate::NamedCamera;

/// Where the focus comes from.
#[derive(Clone, Debug, PartialEq)]
pub enum FocusChoice {
    /// A distance from the camera centre, in scene units.
    Distance(f64),
    /// A training photo's learned focus (and, for the lens variant, aperture).
    FromView(String),
    /// The surface under pixel (x, y) of the rendered view.
    At(u32, u32),
    /// Every training photo its own learned lens; other views sharp.
    AsPhotographed,
}

/// What a refocused render asks for.
#[derive(Clone, Debug, PartialEq)]
pub struct RefocusJob {
    pub focus: FocusChoice,
    /// Multiplies the learned circles of confusion (1 as photographed, 0 sharp).
    pub aperture: f64,
    /// `None`: F where training learned it, else the mean of the sets.
    pub composite: Option<CompositeMode>,
}

/// A scene's lens model, loaded and checked against the scene.
pub struct LensScene {
    pub model: LensModel,
    pub config: CocConfig,
    /// Names of the training views, in the model's order.
    pub train_views: Vec<String>,
}

impl LensScene {
    /// The scene's lens model; a clear error naming what is needed when it has none.
    pub fn load(scene: &Scene, scene_dir: &Path) -> Result<Self, StageError> {
        let Some(stored) = scene.lens_model.as_deref() else {
            let method = scene
                .history
                .iter()
                .rev()
                .find(|h| h.stage == "train")
                .and_then(|h| h.options.get("method").and_then(|m| m.as_str()))
                .unwrap_or("unknown");
            return Err(StageError::Input(format!(
                "{}: this scene has no lens model (it was trained with --method {method}); \
                 refocusing needs a scene trained with `cocog train --method cocog`",
                scene_dir.display()
            )));
        };
        let path = Scene::resolve(scene_dir, stored);
        let model = LensModel::load(&path).map_err(|e| StageError::Input(e.to_string()))?;
        let variant = CocVariant::parse(&model.variant).ok_or_else(|| {
            StageError::Input(format!(
                "{}: unknown variant {:?}",
                path.display(),
                model.variant
            ))
        })?;
        let config = CocConfig {
            variant,
            copies: model.copies,
            width: model.width,
            centred: model.centred,
            modulate_base: model.modulate_base,
        };
        let train_views: Vec<String> = scene
            .views
            .iter()
            .filter(|v| v.split == Split::Train)
            .map(|v| v.name.clone())
            .collect();
        if !model.focus_distances.is_empty() && model.focus_distances.len() != train_views.len() {
            return Err(StageError::Input(format!(
                "{}: {} learned focus distances for {} training views in scene.json",
                path.display(),
                model.focus_distances.len(),
                train_views.len()
            )));
        }
        if model.focus_distances.is_empty() {
            return Err(StageError::Input(format!(
                "{}: training stopped before the blurred phase, so no lens was learned; train \
                 past --blur-start",
                path.display()
            )));
        }
        Ok(Self {
            model,
            config,
            train_views,
        })
    }

    /// A training view's index in the model, or a clear error.
    pub fn train_index(&self, name: &str) -> Result<usize, StageError> {
        self.train_views
            .iter()
            .position(|v| v == name || stem(v) == name)
            .ok_or_else(|| {
                StageError::Options(format!(
                    "no training view named {name:?} (training views: {})",
                    self.train_views.join(", ")
                ))
            })
    }

    /// The lens variant's aperture for renders that are not one photo's: the median learned.
    fn typical_aperture(&self) -> f32 {
        let mut a = self.model.apertures.clone();
        a.sort_by(f32::total_cmp);
        a.get(a.len() / 2).copied().unwrap_or(0.0)
    }

    /// The engine's refocusing renderer for these Gaussians.
    pub fn renderer<'c>(
        &self,
        ctx: &'c GpuContext,
        gaussians: &cocog_engine::GaussianParams,
    ) -> Result<Refocus<'c>, StageError> {
        let m = &self.model;
        let frame = Frame {
            origin: m.origin,
            scale: m.scale,
        };
        Refocus::new(
            ctx,
            self.config,
            m.compositor_channels,
            frame,
            gaussians,
            &m.mlp,
            &m.compositor,
        )
        .map_err(|e| StageError::Input(format!("lens model: {e}")))
    }

    /// Renders `view` as `job` asks; `None` as the lens when the view is rendered sharp
    /// (`--as-photographed` on a view without a learned lens).
    pub fn render(
        &self,
        renderer: &mut Refocus<'_>,
        view: &NamedCamera,
        background: [f32; 3],
        job: &RefocusJob,
    ) -> Result<(RenderedImage, Option<Lens>), StageError> {
        let lens = match &job.focus {
            FocusChoice::AsPhotographed => match self.train_index(&view.name) {
                Ok(k) => Some(self.photo_lens(k, job)),
                Err(_) => None,
            },
            FocusChoice::FromView(name) => Some(self.photo_lens(self.train_index(name)?, job)),
            FocusChoice::Distance(d) => Some(self.lens_at(*d, job)),
            FocusChoice::At(x, y) => {
                let sharp = renderer
                    .render_sharp(&view.camera, background)
                    .map_err(StageError::other)?;
                Some(self.lens_at(distance_at(&sharp, &view.camera, *x, *y)?, job))
            }
        };
        let img = match &lens {
            Some(l) => renderer.render(&view.camera, background, l),
            None => renderer.render_sharp(&view.camera, background),
        }
        .map_err(StageError::other)?;
        Ok((img, lens))
    }

    fn composite(&self, job: &RefocusJob) -> CompositeMode {
        job.composite.unwrap_or(if self.model.compositor_trained {
            CompositeMode::Learned
        } else {
            CompositeMode::Uniform
        })
    }

    fn photo_lens(&self, k: usize, job: &RefocusJob) -> Lens {
        Lens {
            focus_distance: self.model.focus_distances[k],
            aperture: job.aperture as f32,
            learned_aperture: self.model.apertures.get(k).copied().unwrap_or(0.0),
            composite: self.composite(job),
        }
    }

    fn lens_at(&self, distance: f64, job: &RefocusJob) -> Lens {
        Lens {
            focus_distance: distance as f32,
            aperture: job.aperture as f32,
            learned_aperture: self.typical_aperture(),
            composite: self.composite(job),
        }
    }
}

fn stem(name: &str) -> &str {
    name.rsplit_once('.').map_or(name, |(s, _)| s)
}

/// The distance from the camera centre of the surface seen at pixel (x, y): the render's
/// expected depth along the optical axis, along that pixel's ray.
pub fn distance_at(
    img: &RenderedImage,
    camera: &Camera,
    x: u32,
    y: u32,
) -> Result<f64, StageError> {
    if x >= img.width || y >= img.height {
        return Err(StageError::Options(format!(
            "option 'focus_at': pixel ({x}, {y}) is outside the {}×{} render",
            img.width, img.height
        )));
    }
    let i = (y * img.width + x) as usize;
    let alpha = img.alpha[i];
    if alpha < 0.5 {
        return Err(StageError::Options(format!(
            "option 'focus_at': nothing solid at pixel ({x}, {y}) (coverage {alpha:.2}); pick a \
             pixel on the scene"
        )));
    }
    let z = f64::from(img.depth[i] / alpha);
    let rx = (f64::from(x) + 0.5 - camera.cx) / camera.fx;
    let ry = (f64::from(y) + 0.5 - camera.cy) / camera.fy;
    Ok(z * (1.0 + rx * rx + ry * ry).sqrt())
}
