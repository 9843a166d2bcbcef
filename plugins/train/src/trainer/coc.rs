//! CoCoGaussian's state on the GPU: h_θ, the compositor F, the learned focus distances and
//! their Adam moments, and the (M + 1)-image batch a blurred step renders.

use cocog_engine::coc::{CocKernels, CocStep, init_weights};
use cocog_engine::nn::{Compositor, CompositorConfig};
use cocog_engine::{AdamMoments, Batch, Camera, GpuBuffer, GpuContext, ImageSpec, ParamBuffers};

use crate::{CocCheckpoint, CocTrainConfig, FocusState, MomentState, TrainError};

/// The per-photo lens parameters and the frame h_θ works in. Lengths are divided by `scale`
/// (the largest camera-to-Gaussian distance at the blur start, as the released code divides
/// its focus distances) and positions measured from `origin` (the mean training camera
/// centre), so one learning rate and one initialisation suit any scene unit.
#[derive(Debug)]
pub(super) struct Focus {
    /// Per training view d_F / scale.
    pub values: GpuBuffer,
    pub moments: AdamMoments,
    /// Per training view the lens variant's aperture a / scale (unused by the others).
    pub apertures: GpuBuffer,
    pub aperture_moments: AdamMoments,
    pub scale: f32,
    pub origin: [f32; 3],
}

#[derive(Debug)]
pub(super) struct CocState {
    pub config: CocTrainConfig,
    pub kernels: CocKernels,
    pub compositor: Compositor,
    pub weights: GpuBuffer,
    pub weights_m: AdamMoments,
    pub f_params: GpuBuffer,
    pub f_m: AdamMoments,
    /// Set at the blur start, from the Gaussians of that moment.
    pub focus: Option<Focus>,
    /// The M + 1 sets of the current step; its parameters are replaced every step.
    pub batch: Option<Batch>,
}

impl CocState {
    pub fn new(ctx: &GpuContext, config: CocTrainConfig, seed: u64) -> Self {
        let kernels = CocKernels::new(ctx, config.net);
        let mlp = config.net.mlp();
        let mut weights = init_weights(&mlp, seed ^ 0x6C0C_0000_0000_0001);
        let (_, fan_out, w, b) = mlp.layers[3];
        weights[w..b + fan_out]
            .iter_mut()
            .for_each(|v| *v *= config.head_init_scale);
        let compositor = Compositor::new(
            ctx,
            CompositorConfig::with_channels(config.compositor_channels),
        );
        let f_init = compositor.init_params(seed ^ 0x6C0C_0000_0000_0002);
        Self {
            weights_m: AdamMoments::new(ctx, weights.len() as u32),
            weights: ctx.storage_from("coc weights", &weights),
            f_m: AdamMoments::new(ctx, f_init.len() as u32),
            f_params: ctx.storage_from("compositor params", &f_init),
            compositor,
            kernels,
            focus: None,
            batch: None,
            config,
        }
    }

    /// The paper leaves the start of its aperture K open. The untrained head's softplus(≈ 0)
    /// ≈ 0.69 spreads the copies over a circle of confusion of about a hundred pixels, and the
    /// base collapsed at the blur start on both dev scenes (BENCHMARKS.md). So the head's bias
    /// starts K where the lens variant's start puts it at each photo's focus distance (its
    /// K = a·d), averaged over the photos; the head's weights still vary it per Gaussian.
    fn start_paper_aperture(&self, ctx: &GpuContext, k: usize, focus: &[f32], apertures: &[f32]) {
        let n = focus.len().max(1) as f64;
        let k0 = focus
            .iter()
            .zip(apertures)
            .map(|(&d, &a)| f64::from(d) * f64::from(a))
            .sum::<f64>()
            / n;
        if !(k0 > 0.0 && k0.is_finite()) {
            return;
        }
        let bias = softplus_inverse(k0) as f32;
        let (_, _, _, b) = self.config.net.mlp().layers[3];
        let at = ((b + k) * std::mem::size_of::<f32>()) as u64;
        ctx.queue
            .write_buffer(&self.weights, at, bytemuck::bytes_of(&bias));
    }

    /// The lens model of a checkpoint, which must have the layout `config` asks for.
    pub fn restore(
        ctx: &GpuContext,
        config: CocTrainConfig,
        k: &CocCheckpoint,
    ) -> Result<Self, TrainError> {
        let net = config.net;
        let describe = |v: &str, m: u32, w: u32, c: bool, b: bool, f: u32| {
            format!(
                "(variant {v}, {m} copies, width {w}, centred {c}, base modulated {b}, {f} \
                 compositor channels)"
            )
        };
        let want = describe(
            net.variant.name(),
            net.copies,
            net.width,
            net.centred,
            net.modulate_base,
            config.compositor_channels,
        );
        let have = describe(
            &k.variant,
            k.copies,
            k.width,
            k.centred,
            k.modulate_base,
            k.compositor_channels,
        );
        if want != have {
            return Err(TrainError::Invalid(format!(
                "the checkpoint's lens model is {have}; this run asks for {want}"
            )));
        }
        let mut state = Self::new(ctx, config, 0);
        let (mlp_len, f_len) = (net.mlp().len, state.compositor.layout().len);
        if k.mlp.len() != mlp_len || k.compositor.len() != f_len {
            return Err(TrainError::Invalid(format!(
                "the checkpoint's lens model has {} h_θ and {} compositor parameters, the \
                 layout needs {mlp_len} and {f_len}",
                k.mlp.len(),
                k.compositor.len()
            )));
        }
        state.weights = ctx.storage_from("coc weights", &k.mlp);
        state.weights_m = upload(ctx, &k.mlp_moments);
        state.f_params = ctx.storage_from("compositor params", &k.compositor);
        state.f_m = upload(ctx, &k.compositor_moments);
        state.focus = k.focus.as_ref().map(|f| Focus {
            values: ctx.storage_from("focus", &f.values),
            moments: upload(ctx, &f.moments),
            apertures: ctx.storage_from("apertures", &f.apertures),
            aperture_moments: upload(ctx, &f.aperture_moments),
            scale: f.scale,
            origin: f.origin,
        });
        Ok(state)
    }

    /// Reads the lens model and its optimiser state back for a checkpoint.
    pub fn checkpoint(&self, ctx: &GpuContext, views: usize) -> Result<CocCheckpoint, TrainError> {
        let net = &self.config.net;
        let focus = match &self.focus {
            Some(f) => Some(FocusState {
                values: ctx.read(&f.values, views)?,
                moments: download(ctx, &f.moments)?,
                apertures: ctx.read(&f.apertures, views)?,
                aperture_moments: download(ctx, &f.aperture_moments)?,
                scale: f.scale,
                origin: f.origin,
            }),
            None => None,
        };
        Ok(CocCheckpoint {
            variant: net.variant.name().to_owned(),
            copies: net.copies,
            width: net.width,
            centred: net.centred,
            modulate_base: net.modulate_base,
            compositor_channels: self.config.compositor_channels,
            starts: Some([self.config.blur_start, self.config.composite_start]),
            mlp: ctx.read(&self.weights, net.mlp().len)?,
            mlp_moments: download(ctx, &self.weights_m)?,
            compositor: ctx.read(&self.f_params, self.compositor.layout().len)?,
            compositor_moments: download(ctx, &self.f_m)?,
            focus,
        })
    }

    /// What a refocused render needs: the weights, the frame and the learned lenses.
    pub fn lens_model(
        &self,
        ctx: &GpuContext,
        views: usize,
        iteration: u32,
    ) -> Result<cocog_formats::lens_model::LensModel, TrainError> {
        let net = &self.config.net;
        let (frame, apertures) = match &self.focus {
            Some(f) => ((f.origin, f.scale), ctx.read(&f.apertures, views)?),
            None => (([0.0; 3], 1.0), Vec::new()),
        };
        Ok(cocog_formats::lens_model::LensModel {
            origin: frame.0,
            scale: frame.1,
            apertures,
            variant: net.variant.name().to_owned(),
            copies: net.copies,
            width: net.width,
            centred: net.centred,
            modulate_base: net.modulate_base,
            compositor_channels: self.config.compositor_channels,
            compositor_trained: self.config.composites_at(iteration),
            mlp: ctx.read(&self.weights, net.mlp().len)?,
            compositor: ctx.read(&self.f_params, self.compositor.layout().len)?,
            focus_distances: self
                .focus_distances(ctx, views)?
                .iter()
                .map(|d| *d as f32)
                .collect(),
        })
    }

    pub fn sets(&self) -> u32 {
        self.config.net.copies + 1
    }

    /// Initialises the focus distances as the released code does at its blur start: per view,
    /// the mean distance from its camera centre to the Gaussians, over the largest such
    /// distance of any view. The lens variant's apertures start where a point at half the
    /// focus distance blurs over 2 pixels: wide enough that the copies' spread has a
    /// gradient, narrow enough not to scatter the scene.
    pub fn init_focus(&mut self, ctx: &GpuContext, means: &[[f32; 3]], cameras: &[Camera]) {
        let centres: Vec<[f64; 3]> = cameras.iter().map(camera_centre).collect();
        let mut max_depth: f64 = 0.0;
        let means_of: Vec<f64> = centres
            .iter()
            .map(|c| {
                let mut sum = 0.0;
                for m in means {
                    let d = (0..3)
                        .map(|k| (f64::from(m[k]) - c[k]).powi(2))
                        .sum::<f64>()
                        .sqrt();
                    max_depth = max_depth.max(d);
                    sum += d;
                }
                sum / means.len().max(1) as f64
            })
            .collect();
        let scale = if max_depth > 0.0 { max_depth } else { 1.0 };
        // A known or estimated start where there is one, else the mean distance.
        let start: Vec<f64> = match &self.config.initial_focus {
            Some(known) if known.len() == means_of.len() => known
                .iter()
                .zip(&means_of)
                .map(|(&k, &m)| if k.is_finite() && k > 0.0 { k } else { m })
                .collect(),
            _ => means_of,
        };
        let values: Vec<f32> = start.iter().map(|d| (d / scale) as f32).collect();
        // CoC in pixels = f·A·|1/d − 1/d_F|; at d = d_F/2 that is f·A/d_F = 2 → A = 2·d_F/f.
        let apertures: Vec<f32> = values
            .iter()
            .zip(cameras)
            .map(|(p, c)| (2.0 * f64::from(*p) / c.fx.max(1.0)) as f32)
            .collect();
        if let Some(k) = self.config.net.heads().aperture {
            self.start_paper_aperture(ctx, k, &values, &apertures);
        }
        let n = centres.len().max(1) as f64;
        let origin = [0, 1, 2].map(|k| (centres.iter().map(|c| c[k]).sum::<f64>() / n) as f32);
        self.focus = Some(Focus {
            moments: AdamMoments::new(ctx, values.len() as u32),
            values: ctx.storage_from("focus", &values),
            aperture_moments: AdamMoments::new(ctx, apertures.len() as u32),
            apertures: ctx.storage_from("apertures", &apertures),
            scale: scale as f32,
            origin,
        });
    }

    /// The step's view for the CoC kernels (`init_focus` must have run).
    pub fn step_for(&self, view: usize, camera: &Camera) -> Result<CocStep, TrainError> {
        let focus = self.focus.as_ref().ok_or(TrainError::Poisoned)?;
        Ok(CocStep {
            view: view as u32,
            camera_centre: camera_centre(camera).map(|v| v as f32),
            focus_scale: focus.scale,
            origin: focus.origin,
            aperture: 1.0,
        })
    }

    /// Points the (M + 1)-image batch in `slot` at `params` (means, scales, rotations of every
    /// set; opacities and SH read from the base's rows), all rendered from `camera`. A function
    /// of the slot alone, so the batch can be borrowed beside the rest of the state.
    pub fn aim<'b>(
        slot: &'b mut Option<Batch>,
        ctx: &GpuContext,
        params: ParamBuffers,
        sets: u32,
        camera: Camera,
        background: [f32; 3],
    ) -> Result<&'b Batch, TrainError> {
        let n = params.num_gaussians / sets.max(1);
        let specs: Vec<ImageSpec> = (0..sets)
            .map(|m| ImageSpec {
                camera,
                background,
                first: m * n,
                count: n,
                crop: None,
            })
            .collect();
        match slot {
            Some(b) => {
                b.params = params;
                b.set_images(ctx, specs)?;
            }
            None => *slot = Some(Batch::new(ctx, params, specs)?),
        }
        slot.as_ref().ok_or(TrainError::Poisoned)
    }

    /// The lens variant's learned apertures per training view, in scene units (empty before
    /// the blurred phase).
    pub fn apertures(&self, ctx: &GpuContext, views: usize) -> Result<Vec<f64>, TrainError> {
        let Some(f) = &self.focus else {
            return Ok(Vec::new());
        };
        let v: Vec<f32> = ctx.read(&f.apertures, views)?;
        Ok(v.iter()
            .map(|x| f64::from(*x) * f64::from(f.scale))
            .collect())
    }

    /// Learned focus distances per training view, in scene units.
    pub fn focus_distances(&self, ctx: &GpuContext, views: usize) -> Result<Vec<f64>, TrainError> {
        let Some(f) = &self.focus else {
            return Ok(Vec::new());
        };
        let v: Vec<f32> = ctx.read(&f.values, views)?;
        Ok(v.iter()
            .map(|x| f64::from(*x) * f64::from(f.scale))
            .collect())
    }
}

fn upload(ctx: &GpuContext, s: &MomentState) -> AdamMoments {
    AdamMoments {
        len: s.m.len() as u32,
        m: ctx.storage_from("adam m", &s.m),
        v: ctx.storage_from("adam v", &s.v),
    }
}

fn download(ctx: &GpuContext, m: &AdamMoments) -> Result<MomentState, TrainError> {
    let len = m.len as usize;
    Ok(MomentState {
        m: ctx.read(&m.m, len)?,
        v: ctx.read(&m.v, len)?,
    })
}

/// The camera centre in world coordinates (the translation of `world_from_camera`).
pub(super) fn camera_centre(c: &Camera) -> [f64; 3] {
    let m = c.world_from_camera;
    [m[0][3], m[1][3], m[2][3]]
}

/// x with softplus(x) = y, for y > 0 (ln(eʸ − 1), without cancelling for small y).
fn softplus_inverse(y: f64) -> f64 {
    y.exp_m1().ln()
}
