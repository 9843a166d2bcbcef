//! Rendering a fixed set of Gaussians from many cameras: upload once, one forward per view.

use std::path::Path;

use cocog_engine::{
    Batch, Camera, EngineError, GaussianParams, GpuContext, ImageSpec, ParamBuffers, RenderedImage,
    Renderer,
};
use cocog_pipeline::{Scene, StageError};

/// A scene's Gaussians on the GPU, ready to render from any camera at any resolution.
pub struct SceneRenderer<'c> {
    ctx: &'c GpuContext,
    renderer: Renderer,
    /// `None` only while a batch holds them (`Batch::new` takes them by value).
    params: Option<ParamBuffers>,
    pub background: [f32; 3],
}

impl<'c> SceneRenderer<'c> {
    pub fn new(
        ctx: &'c GpuContext,
        gaussians: &GaussianParams,
        background: [f32; 3],
    ) -> Result<Self, EngineError> {
        Ok(Self {
            ctx,
            renderer: Renderer::new(ctx),
            params: Some(ParamBuffers::upload(ctx, &[gaussians])?),
            background,
        })
    }

    /// Colour, alpha and expected depth (Σ wᵢ·zᵢ, not divided by alpha) seen by `camera`, at
    /// any size: a frame too large for one buffer binding renders in bands of rows.
    pub fn render(&mut self, camera: &Camera) -> Result<RenderedImage, EngineError> {
        let params = self
            .params
            .take()
            .ok_or_else(|| EngineError::Invalid("an earlier render failed".into()))?;
        let spec = ImageSpec {
            camera: *camera,
            background: self.background,
            first: 0,
            count: params.num_gaussians,
            crop: None,
        };
        let mut batch = Batch::new(self.ctx, params, vec![spec])?;
        let result = self.renderer.render_frame(self.ctx, &mut batch, spec);
        self.params = Some(batch.params);
        Ok(result?.image)
    }
}

/// The Gaussians a trained scene names in its `gaussians` field.
pub fn load_gaussians(scene: &Scene, scene_dir: &Path) -> Result<GaussianParams, StageError> {
    let stored = scene.gaussians.as_deref().ok_or_else(|| {
        StageError::Input(format!(
            "{}: scene.json has no field `gaussians`; render a trained scene (the output of \
             `cocog train`)",
            scene_dir.display()
        ))
    })?;
    let path = Scene::resolve(scene_dir, stored);
    let splats = cocog_formats::ply::read_splats(&path)
        .map_err(|e| StageError::Input(format!("scene.json `gaussians`: {e}")))?;
    if splats.is_empty() {
        return Err(StageError::Input(format!(
            "{}: no Gaussians to render",
            path.display()
        )));
    }
    Ok(GaussianParams::from(&splats))
}
