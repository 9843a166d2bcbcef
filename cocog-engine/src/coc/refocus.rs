//! Depth of field after the fact: a trained scene's base Gaussians, expanded by its h_θ for
//! any camera, focus distance and aperture, rendered as M + 1 sets and composited by its F
//! (or averaged). Aperture 0 is the plain sharp render.

use super::{CocConfig, CocKernels, CocStep};
use crate::core::{GpuBuffer, GpuContext, Workspace};
use crate::nn::{CompositeMode, Compositor, CompositorConfig};
use crate::{
    Batch, Camera, EngineError, GaussianParams, ImageSpec, ParamBuffers, RenderedImage, Renderer,
};

/// How a refocused image is made.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Lens {
    /// Distance from the camera centre that is in focus (scene units).
    pub focus_distance: f32,
    /// Multiplies the learned circles of confusion: 1 as photographed, 0 a pinhole.
    pub aperture: f32,
    /// The lens variant's learned aperture a (normalised, as trained) that `aperture`
    /// multiplies: one photo's, or a typical one; ignored by the other variants.
    pub learned_aperture: f32,
    pub composite: CompositeMode,
}

/// The normalised frame h_θ was trained in: positions from `origin`, lengths over `scale`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frame {
    pub origin: [f32; 3],
    pub scale: f32,
}

/// A trained scene and its lens model on the GPU.
pub struct Refocus<'c> {
    ctx: &'c GpuContext,
    kernels: CocKernels,
    compositor: Compositor,
    renderer: Renderer,
    /// `None` only while a batch holds them.
    base: Option<ParamBuffers>,
    weights: GpuBuffer,
    f_params: GpuBuffer,
    frame: Frame,
    ws: Workspace,
}

impl<'c> Refocus<'c> {
    /// `mlp` and `compositor` must follow `config`'s and `channels`' layouts.
    pub fn new(
        ctx: &'c GpuContext,
        config: CocConfig,
        channels: u32,
        frame: Frame,
        gaussians: &GaussianParams,
        mlp: &[f32],
        compositor: &[f32],
    ) -> Result<Self, EngineError> {
        if !(frame.scale.is_finite() && frame.scale > 0.0) {
            return Err(EngineError::Invalid(format!(
                "the lens model's scene scale is {}",
                frame.scale
            )));
        }
        let f = Compositor::new(ctx, CompositorConfig::with_channels(channels));
        let (want_mlp, want_f) = (config.mlp().len, f.layout().len);
        if mlp.len() != want_mlp || compositor.len() != want_f {
            return Err(EngineError::Invalid(format!(
                "the lens model has {} h_θ and {} compositor weights; its layout needs \
                 {want_mlp} and {want_f}",
                mlp.len(),
                compositor.len()
            )));
        }
        Ok(Self {
            ctx,
            kernels: CocKernels::new(ctx, config),
            compositor: f,
            renderer: Renderer::new(ctx),
            base: Some(ParamBuffers::upload(ctx, &[gaussians])?),
            weights: ctx.storage_from("refocus mlp", mlp),
            f_params: ctx.storage_from("refocus compositor", compositor),
            frame,
            ws: Workspace::default(),
        })
    }

    /// Plans for at most `bytes` per buffer binding instead of the device's limit (tests of
    /// the size checks and of banded sharp renders at small sizes).
    pub fn with_binding_limit(mut self, bytes: u64) -> Self {
        self.renderer = std::mem::replace(&mut self.renderer, Renderer::new(self.ctx))
            .with_binding_limit(bytes);
        self.compositor.set_binding_limit(bytes);
        self
    }

    /// The base Gaussians alone (what aperture 0 gives, and what test views are scored on), at
    /// any size: in bands of rows where the frame outgrows a buffer binding.
    pub fn render_sharp(
        &mut self,
        camera: &Camera,
        background: [f32; 3],
    ) -> Result<RenderedImage, EngineError> {
        let base = self.take_base()?;
        let n = base.num_gaussians;
        let spec = ImageSpec {
            camera: *camera,
            background,
            first: 0,
            count: n,
            crop: None,
        };
        let mut batch = Batch::new(self.ctx, base, vec![spec])?;
        let result = self.renderer.render_frame(self.ctx, &mut batch, spec);
        self.base = Some(batch.params);
        Ok(result?.image)
    }

    /// The view from `camera` through `lens`. Depth is the base Gaussians' (the surface in
    /// focus-independent terms); colour and alpha are the composite's.
    pub fn render(
        &mut self,
        camera: &Camera,
        background: [f32; 3],
        lens: &Lens,
    ) -> Result<RenderedImage, EngineError> {
        if !(lens.focus_distance.is_finite() && lens.focus_distance > 0.0) {
            return Err(EngineError::Invalid(format!(
                "focus distance {} (must be a positive length)",
                lens.focus_distance
            )));
        }
        if !(lens.aperture.is_finite() && lens.aperture >= 0.0) {
            return Err(EngineError::Invalid(format!(
                "aperture {} (must be 0 or more)",
                lens.aperture
            )));
        }
        if lens.aperture > 0.0 {
            self.check_size(camera, lens.composite)?;
        }
        let sharp = self.render_sharp(camera, background)?;
        if lens.aperture == 0.0 {
            return Ok(sharp);
        }
        let ctx = self.ctx;
        let base = self.take_base()?;
        let n = base.num_gaussians;
        let m = camera.world_from_camera;
        let step = CocStep {
            view: 0,
            camera_centre: [m[0][3], m[1][3], m[2][3]].map(|v| v as f32),
            focus_scale: self.frame.scale,
            origin: self.frame.origin,
            aperture: lens.aperture,
        };
        let focus = ctx.storage_from("refocus focus", &[lens.focus_distance / self.frame.scale]);
        let learned = ctx.storage_from("refocus aperture", &[lens.learned_aperture]);
        let mut rec = ctx.recorder();
        let exp = self.kernels.encode_forward(
            &mut rec,
            &mut self.ws,
            &self.weights,
            &base.means,
            &base.log_scales,
            &base.quats,
            &focus,
            &learned,
            n,
            &step,
        );
        let sets = self.kernels.sets(&base, &exp);
        rec.submit();
        self.base = Some(base);
        let count = self.kernels.config().copies + 1;
        let specs = (0..count)
            .map(|s| ImageSpec {
                camera: *camera,
                background,
                first: s * n,
                count: n,
                crop: None,
            })
            .collect();
        let batch = Batch::new(ctx, sets, specs)?;
        let state = self.renderer.forward(ctx, &batch)?;
        let (w, h) = (batch.width(), batch.height());
        let mut rec = ctx.recorder();
        let out = self.compositor.encode_forward(
            &mut rec,
            &mut self.ws,
            &self.f_params,
            &state.rgba,
            w,
            h,
            count,
            lens.composite,
        );
        rec.submit();
        let rgba: Vec<[f32; 4]> = ctx.read(&out.blend, (w * h) as usize)?;
        Ok(RenderedImage {
            width: w,
            height: h,
            color: rgba.iter().map(|p| [p[0], p[1], p[2]]).collect(),
            alpha: rgba.iter().map(|p| p[3]).collect(),
            depth: sharp.depth,
        })
    }

    /// A refocused view renders M + 1 sets at once and, composited by F, holds the feature
    /// maps of as many renders as a binding holds (at least one: channels floats a pixel).
    /// Unlike the sharp render it cannot go in bands (F's instance norm sees the whole image),
    /// so a view whose renders, or one render's maps, outgrow one buffer binding is refused
    /// with the size that fits.
    fn check_size(&self, camera: &Camera, composite: CompositeMode) -> Result<(), EngineError> {
        let (w, h) = (camera.width, camera.height);
        let pixels = u64::from(w) * u64::from(h);
        let sets = u64::from(self.kernels.config().copies + 1);
        let channels = self.compositor.layout().channels;
        let rgba = 16 * pixels * sets;
        let maps = CompositorConfig::with_channels(channels as u32).map_bytes(pixels, 1);
        let (need, what, also) = if composite == CompositeMode::Learned && maps > rgba {
            (
                maps,
                format!("the compositor's {channels}-channel maps of one render"),
                ", or average the renders (--composite mean)",
            )
        } else {
            (rgba, format!("{sets} rgba renders"), "")
        };
        let limit = self.renderer.binding_limit(self.ctx);
        if need <= limit {
            return Ok(());
        }
        let mib = |b: u64| b as f64 / f64::from(1 << 20);
        Err(EngineError::Invalid(format!(
            "a refocused {w}×{h} view needs a {:.0} MiB GPU buffer binding ({what}) and this \
             adapter binds at most {:.0} MiB: render it smaller (--downscale {} or more){also}",
            mib(need),
            mib(limit),
            (need as f64 / limit as f64).sqrt().ceil()
        )))
    }

    fn take_base(&mut self) -> Result<ParamBuffers, EngineError> {
        self.base
            .take()
            .ok_or_else(|| EngineError::Invalid("an earlier render failed".into()))
    }
}
