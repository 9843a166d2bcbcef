//! The training loop: one view per iteration, forward → loss → backward → per-group Adam.

use std::collections::VecDeque;

use cocog_engine::{
    Adam, AdamConfig, AdamMoments, Batch, Camera, GaussianParams, GpuBuffer, GpuContext, ImageLoss,
    ImageSpec, Kernel, LossOutput, MAX_SH_DEGREE, ParamBuffers, Readback, Recorder, RenderedImage,
    Renderer, Workspace, sh_coeffs_per_channel,
};

use crate::{
    DensifyConfig, GradStats, SplitMix64, TrainConfig, TrainError, ViewOrder, scene_extent,
};

mod bands;
mod binding;
mod cap;
mod capacity;
mod coc;
mod coc_step;
mod density;
mod focus;
mod sh_growth;
mod snapshot;

pub use sh_growth::{record_widen_sh, widen_kernel, widen_sh};

/// Steps the CPU may run ahead of the GPU; their read-backs arrive this many steps late.
const IN_FLIGHT: usize = 3;

/// One training image: its camera and its linear RGB pixels, row-major, `width × height`.
#[derive(Clone, Debug)]
pub struct TrainView {
    pub camera: Camera,
    pub image: Vec<[f32; 3]>,
}

/// What one iteration did.
#[derive(Clone, Debug, PartialEq)]
pub struct StepStats {
    /// 1-based, as INRIA counts (schedules are evaluated at this value).
    pub iteration: u32,
    pub view: usize,
    pub sh_degree: u32,
    /// Gaussians the next iteration trains. Right after a GPU densification that is twice
    /// the count before it (the rows past the new count buried) until the new count arrives,
    /// a few iterations later; `Trainer::gaussians` never includes buried rows.
    pub num_gaussians: u32,
    /// Loss and PSNR of earlier iterations (divisible by `TrainConfig::loss_every`) whose
    /// asynchronous read-back arrived during this one, oldest first.
    pub readings: Vec<Reading>,
    /// Wall time per phase, only while `Trainer::set_profiling(true)`.
    pub phases: Option<PhaseTimes>,
    /// Bands of rows the view was trained in: 1 when its frame fits one buffer binding.
    pub bands: u32,
}

/// The loss and PSNR of one logged iteration, read back without stalling the GPU.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Reading {
    pub iteration: u32,
    pub view: usize,
    /// Gaussians and SH degree the iteration trained.
    pub num_gaussians: u32,
    pub sh_degree: u32,
    pub loss: f64,
    /// dB, of the render clamped to [0, 1] as a saved image would be, against the view.
    pub psnr: f64,
}

/// What a step's read-back slot holds besides the renderer's status words.
#[derive(Debug)]
struct InFlight {
    iteration: u32,
    view: usize,
    num_gaussians: u32,
    sh_degree: u32,
    /// The loss whose partial sums follow the status, on logging iterations.
    loss: Option<LossOutput>,
}

/// What a read-back slot carries: a step's status (and loss), or the Gaussian count a
/// densification left.
#[derive(Debug)]
enum Pending {
    Step(InFlight),
    Count,
}

/// A densification whose count has not reached the CPU yet.
#[derive(Debug)]
struct PendingCount {
    /// [after, kept, cloned, split] as u32.
    counts: GpuBuffer,
    /// The count before it.
    before: u32,
}

/// Seconds one iteration spent in each phase. Profiling waits for the GPU after every phase,
/// which serialises CPU and GPU work: the sum is slower than an unprofiled iteration.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PhaseTimes {
    /// Projection, sorting, rasterisation and the loss with its gradient.
    pub forward: f64,
    pub backward: f64,
    /// Adam on every group.
    pub optimizer: f64,
    /// Gradient statistics, densify/prune decisions and re-uploads, opacity resets.
    pub density: f64,
    /// CoCoGaussian: h_θ and the expansion into M + 1 sets, forward and adjoint.
    pub coc_net: f64,
    /// CoCoGaussian: the compositor F (or the mean), forward and backward.
    pub compositor: f64,
}

impl PhaseTimes {
    pub fn total(&self) -> f64 {
        self.forward
            + self.backward
            + self.optimizer
            + self.density
            + self.coc_net
            + self.compositor
    }

    pub fn add(&mut self, other: &PhaseTimes) {
        self.forward += other.forward;
        self.backward += other.backward;
        self.optimizer += other.optimizer;
        self.density += other.density;
        self.coc_net += other.coc_net;
        self.compositor += other.compositor;
    }
}

/// Measures phases by waiting for the GPU at each boundary; free when disabled.
struct Stopwatch {
    enabled: bool,
    last: std::time::Instant,
    times: PhaseTimes,
}

impl Stopwatch {
    fn new(enabled: bool) -> Self {
        Self {
            enabled,
            last: std::time::Instant::now(),
            times: PhaseTimes::default(),
        }
    }

    /// Seconds since the previous lap, after the GPU finished what `rec` recorded (submitted
    /// here and replaced by a fresh recorder: profiling costs one submission per phase).
    fn lap_recorded<'c>(&mut self, rec: &mut Recorder<'c>) -> Result<f64, TrainError> {
        if !self.enabled {
            return Ok(0.0);
        }
        let ctx = rec.ctx();
        std::mem::replace(rec, ctx.recorder()).submit();
        self.lap(ctx)
    }

    /// Seconds since the previous lap, after the GPU finished what was submitted.
    fn lap(&mut self, ctx: &GpuContext) -> Result<f64, TrainError> {
        if !self.enabled {
            return Ok(0.0);
        }
        ctx.wait()?;
        let now = std::time::Instant::now();
        let dt = (now - self.last).as_secs_f64();
        self.last = now;
        Ok(dt)
    }

    fn result(&self) -> Option<PhaseTimes> {
        self.enabled.then_some(self.times)
    }
}

/// Adam state of each parameter group.
#[derive(Debug)]
struct Moments {
    means: AdamMoments,
    log_scales: AdamMoments,
    quats: AdamMoments,
    opacity_logits: AdamMoments,
    sh: AdamMoments,
}

impl Moments {
    fn new(ctx: &GpuContext, p: &ParamBuffers) -> Self {
        let n = p.num_gaussians;
        let sh = 3 * sh_coeffs_per_channel(p.sh_degree) as u32;
        Self {
            means: AdamMoments::new(ctx, 3 * n),
            log_scales: AdamMoments::new(ctx, 3 * n),
            quats: AdamMoments::new(ctx, 4 * n),
            opacity_logits: AdamMoments::new(ctx, n),
            sh: AdamMoments::new(ctx, sh * n),
        }
    }

    /// Densification left `n` Gaussians in the buffers (`sh` floats of SH per Gaussian).
    fn set_count(&mut self, n: u32, sh: u32) {
        self.means.len = 3 * n;
        self.log_scales.len = 3 * n;
        self.quats.len = 4 * n;
        self.opacity_logits.len = n;
        self.sh.len = sh * n;
    }
}

/// Vanilla 3DGS optimisation of one Gaussian set against posed images, all on the GPU.
pub struct Trainer<'c> {
    ctx: &'c GpuContext,
    config: TrainConfig,
    renderer: Renderer,
    loss: ImageLoss,
    adam: Adam,
    opacity_reset: Kernel,
    widen_sh: Kernel,
    cameras: Vec<Camera>,
    /// Per view, rgba f32 laid out like `ForwardState::rgba` (alpha unused by the loss).
    targets: Vec<GpuBuffer>,
    /// The parameters and the current view's camera. `None` only after a step failed between
    /// taking and returning it (see `Poisoned`).
    batch: Option<Batch>,
    /// Per-step scratch, grown when the Gaussian or intersection count outgrows it.
    ws: Workspace,
    /// Room for (tile, Gaussian) intersections in a step (see `capacity.rs`).
    capacity: u32,
    readback: Readback<Pending>,
    /// Set from a densification until its count arrives; meanwhile steps train 2× the old
    /// count, the rows past the new one buried.
    pending_count: Option<PendingCount>,
    /// Views whose step overflowed the intersection buffers (the GPU skipped its update),
    /// trained again before new ones.
    redo: VecDeque<usize>,
    moments: Moments,
    order: ViewOrder,
    /// Densification statistics.
    stats: GradStats,
    densify: crate::GpuDensify,
    /// Gathers a banded step's bands (`bands.rs`).
    bands_kernels: bands::BandKernels,
    /// The binding frames are planned against (`bands.rs`); the adapter's unless a test
    /// lowers it.
    frame_limit: Option<u64>,
    /// CoCoGaussian's h_θ, F and focus distances, when `config.coc` asks for them.
    coc: Option<coc::CocState>,
    rng: SplitMix64,
    /// The length the world-space rules and the position learning rate are relative to.
    scene_scale: f64,
    /// What depth-weighted pruning calls depth.
    depth_axis: crate::DepthAxis,
    iteration: u32,
    /// Adam's step count for the Gaussians restarts after this iteration (`Resumed`).
    adam_origin: u32,
    profiling: bool,
    /// Densify through the CPU rule even where the doubled set fits a binding.
    cpu_densification: bool,
    /// The most Gaussians this run's buffers can bind (`cap.rs`); density control grows the
    /// set no further, and `capped` says where it stopped.
    most: u32,
    capped: Option<u32>,
}

impl<'c> Trainer<'c> {
    /// Uploads `init` and the target images. All views must share one resolution (the engine
    /// batches by resolution); the scene scale is `config.scene_scale`, or INRIA's camera
    /// extent of their centres when that is `None`.
    pub fn new(
        ctx: &'c GpuContext,
        init: &GaussianParams,
        views: &[TrainView],
        config: TrainConfig,
    ) -> Result<Self, TrainError> {
        check_inputs(init, views, &config)?;
        let params = ParamBuffers::upload(ctx, &[init])?;
        let state = Resumed {
            moments: Moments::new(ctx, &params),
            stats: GradStats::new(ctx, params.num_gaussians),
            // Decorrelated from the view order, which uses the seed as is.
            rng: SplitMix64::new(config.seed ^ 0xD3A5_17F0_0000_0001),
            order: ViewOrder::new(views.len(), config.seed),
            iteration: 0,
            adam_origin: 0,
            params,
            coc: None,
        };
        Self::assemble(ctx, views, config, state)
    }

    /// Everything but the optimisation state, which `state` brings (fresh or restored).
    fn assemble(
        ctx: &'c GpuContext,
        views: &[TrainView],
        config: TrainConfig,
        state: Resumed,
    ) -> Result<Self, TrainError> {
        let (w, h) = (views[0].camera.width, views[0].camera.height);
        // A plain 3DGS step trains a frame past one binding in bands; a CoC step cannot (F's
        // instance norms see whole frames).
        if config.coc.is_some() {
            binding::check(w, h, &config, ctx.binding_limit(), &ctx.adapter_name())
        } else {
            bands::plan(w, h, ctx.binding_limit())
                .and_then(|_| bands::check_targets(w, h, ctx.device.limits().max_buffer_size))
        }
        .map_err(TrainError::Invalid)?;
        cap::check(state.params.num_gaussians, &config, ctx.binding_limit())?;
        let most = cap::most_gaussians(&config, ctx.binding_limit());
        let cameras: Vec<Camera> = views.iter().map(|v| v.camera).collect();
        let scene_scale = match config.scene_scale {
            Some(s) if s.is_finite() && s > 0.0 => s,
            Some(s) => {
                return Err(TrainError::Invalid(format!(
                    "scene scale {s} (must be a positive length)"
                )));
            }
            None => scene_extent(&cameras)?,
        };
        let targets = views
            .iter()
            .map(|v| {
                let rgba: Vec<[f32; 4]> = v.image.iter().map(|c| [c[0], c[1], c[2], 1.0]).collect();
                ctx.storage_from("target", &rgba)
            })
            .collect();
        let spec = ImageSpec {
            camera: cameras[0],
            background: config.background,
            first: 0,
            count: state.params.num_gaussians,
            crop: None,
        };
        let batch = Batch::new(ctx, state.params, vec![spec])?;
        let mut trainer = Self {
            ctx,
            renderer: Renderer::new(ctx),
            loss: ImageLoss::new(ctx),
            adam: Adam::new(ctx),
            opacity_reset: density::opacity_reset_kernel(ctx),
            widen_sh: sh_growth::widen_kernel(ctx),
            densify: crate::GpuDensify::new(ctx),
            bands_kernels: bands::BandKernels::new(ctx),
            frame_limit: None,
            targets,
            moments: state.moments,
            stats: state.stats,
            rng: state.rng,
            coc: match (config.coc.clone(), &state.coc) {
                (Some(c), Some(k)) => Some(coc::CocState::restore(ctx, c, k)?),
                (Some(c), None) => Some(coc::CocState::new(ctx, c, config.seed)),
                (None, _) => None,
            },
            batch: Some(batch),
            ws: Workspace::default(),
            capacity: 0,
            readback: Readback::new(IN_FLIGHT),
            pending_count: None,
            redo: VecDeque::new(),
            order: state.order,
            depth_axis: depth_axis(&cameras),
            cameras,
            scene_scale,
            iteration: state.iteration,
            adam_origin: state.adam_origin,
            profiling: false,
            cpu_densification: false,
            most,
            capped: None,
            config,
        };
        let room = trainer.measure_capacity()?;
        trainer.set_room(room);
        if let Some(c) = trainer.coc.as_ref().filter(|c| c.focus.is_some()) {
            // A resumed blurred phase renders M + 1 copies of every Gaussian from its first step.
            trainer.capacity = trainer.capacity.saturating_mul(c.sets());
        }
        Ok(trainer)
    }

    /// Time every phase of the following steps (`StepStats::phases`); costs a GPU wait per
    /// phase, so only benchmarks turn it on.
    pub fn set_profiling(&mut self, on: bool) {
        self.profiling = on;
    }

    /// Densify through the CPU fallback (read back, `plan_densify`, upload) that sets too large
    /// for a doubled buffer take, whatever their size: what its trainer-level test runs.
    pub fn force_cpu_densification(&mut self, on: bool) {
        self.cpu_densification = on;
    }

    /// Renders as if a buffer binding held `bytes` (tests reach the intersection limit with
    /// it), and holds the room within it.
    /// Trains frames as if a buffer binding held `bytes`: frames larger than that train in
    /// bands of rows (tests reach the banded step at small sizes with it).
    pub fn set_frame_binding_limit(&mut self, bytes: u64) {
        self.frame_limit = Some(bytes);
    }

    /// The binding a frame's per-pixel buffers are planned against.
    fn frame_binding_limit(&self) -> u64 {
        self.frame_limit.unwrap_or_else(|| self.ctx.binding_limit())
    }

    pub fn set_render_binding_limit(&mut self, bytes: u64) {
        self.renderer = Renderer::new(self.ctx).with_binding_limit(bytes);
        self.set_room(self.capacity);
    }

    /// Lowers the most Gaussians density control grows the set to (the adapter's binding sets
    /// it; tests reach it with a small cap).
    pub fn set_gaussian_cap(&mut self, most: u32) {
        self.most = most.min(self.most);
    }

    /// The count density control stopped growing at, when the cap was reached.
    pub fn growth_capped_at(&self) -> Option<u32> {
        self.capped
    }

    pub fn config(&self) -> &TrainConfig {
        &self.config
    }

    /// The scene scale the position learning rate and the world-space density rules use.
    pub fn scene_scale(&self) -> f64 {
        self.scene_scale
    }

    /// Whether step `it` changes the Gaussian set after its optimiser update (densification,
    /// point addition, opacity reset), leaving new Gaussians untrained, so the model worth
    /// scoring "at" `it` is the one before it, as INRIA's test report sees it.
    pub fn restructures_at(&self, it: u32) -> bool {
        self.density_at(it)
            .is_some_and(|d| d.densifies_at(it) || d.adds_points_at(it) || d.resets_opacity_at(it))
    }

    /// The density control that applies at `it`: none on the run's last iteration, whose
    /// children, added points or reset opacities no later step would train (INRIA saves that
    /// iteration's model before its density step, to the same effect). Densifying there cost
    /// sharp-dev 1.5 dB at 7000 iterations: 620 untrained split children in the saved model.
    fn density_at(&self, it: u32) -> Option<&DensifyConfig> {
        self.config
            .densify
            .as_ref()
            .filter(|_| it < self.config.iterations)
    }

    /// Iterations completed.
    pub fn iteration(&self) -> u32 {
        self.iteration
    }

    pub fn num_views(&self) -> usize {
        self.cameras.len()
    }

    pub fn sh_degree(&self) -> u32 {
        self.batch.as_ref().map_or(0, |b| b.params.sh_degree)
    }

    /// The renderer the steps composite with (its blocks and split, as `cocog bench` reports).
    pub fn renderer(&self) -> &Renderer {
        &self.renderer
    }

    /// CoCoGaussian's compositor F (None for plain 3DGS).
    pub fn compositor(&self) -> Option<&cocog_engine::nn::Compositor> {
        self.coc.as_ref().map(|c| &c.compositor)
    }

    pub fn num_gaussians(&self) -> u32 {
        self.batch.as_ref().map_or(0, |b| b.params.num_gaussians)
    }

    /// The parameters (`Poisoned` if a failed step lost them).
    fn params(&self) -> Result<&ParamBuffers, TrainError> {
        self.batch
            .as_ref()
            .map(|b| &b.params)
            .ok_or(TrainError::Poisoned)
    }

    fn params_mut(&mut self) -> Result<&mut ParamBuffers, TrainError> {
        self.batch
            .as_mut()
            .map(|b| &mut b.params)
            .ok_or(TrainError::Poisoned)
    }

    /// The learned focus distance of every training view (scene units), once CoCoGaussian's
    /// blurred phase has started; empty before that and for plain 3DGS.
    pub fn focus_distances(&self) -> Result<Vec<f64>, TrainError> {
        match &self.coc {
            Some(c) => c.focus_distances(self.ctx, self.cameras.len()),
            None => Ok(Vec::new()),
        }
    }

    /// The lens variant's learned aperture diameter of every training view (scene units);
    /// empty for the other methods and variants and before the blurred phase.
    pub fn apertures(&self) -> Result<Vec<f64>, TrainError> {
        match &self.coc {
            Some(c) if c.config.net.variant == cocog_engine::coc::CocVariant::Lens => {
                c.apertures(self.ctx, self.cameras.len())
            }
            _ => Ok(Vec::new()),
        }
    }

    /// CoCoGaussian's lens model for refocused renders (`None` for plain 3DGS).
    pub fn lens_model(&self) -> Result<Option<cocog_formats::lens_model::LensModel>, TrainError> {
        match &self.coc {
            Some(c) => Ok(Some(c.lens_model(
                self.ctx,
                self.cameras.len(),
                self.iteration,
            )?)),
            None => Ok(None),
        }
    }

    /// Room for (tile, Gaussian) intersections a step records with.
    pub fn intersection_capacity(&self) -> u32 {
        self.capacity
    }

    /// Overrides that room (tests force an overflow with it); it grows again on its own, as
    /// soon as counts of earlier steps come back.
    pub fn set_intersection_capacity(&mut self, capacity: u32) {
        self.capacity = capacity;
    }

    /// Waits for every step in flight and returns the readings not yet reported (call at the
    /// end of a run, or before reading results that must include them).
    pub fn finish(&mut self) -> Result<Vec<Reading>, TrainError> {
        let done = self.readback.drain(self.ctx)?;
        self.absorb(done)
    }

    /// One iteration: raise the SH degree if due, pick the next view, optimise on it, densify
    /// and reset opacities when due. Records one submission and waits for nothing but a step
    /// `IN_FLIGHT` iterations old, except that SH growth adds a submission (and the wider
    /// buffers), and that point addition and densifications too large for a buffer binding
    /// go through the CPU.
    pub fn step(&mut self) -> Result<StepStats, TrainError> {
        let it = self.iteration + 1;
        let mut watch = Stopwatch::new(self.profiling);
        let mut done = self.readback.collect(self.ctx)?;
        done.extend(self.readback.throttle(self.ctx)?);
        let readings = self.absorb(done)?;
        let degree = self.config.sh_degree_at(it);
        if degree > self.sh_degree() {
            self.raise_sh_degree(degree)?;
        }
        let view = match self.redo.pop_front() {
            Some(v) => v,
            None => self
                .order
                .next_view()
                .ok_or_else(|| TrainError::Invalid("no training views".into()))?,
        };
        let d = self.density_at(it).cloned();
        let plan = Plan {
            gather_stats: d.as_ref().is_some_and(|d| it < d.until_iter),
            densify: d.as_ref().is_some_and(|d| d.densifies_at(it)),
            reset_opacity: d.as_ref().is_some_and(|d| d.resets_opacity_at(it)),
        };
        let background = self.background_at(it);
        let estimate = self.coc.as_ref().is_some_and(|c| {
            c.focus.is_none()
                && c.config.estimate_focus
                && c.config.initial_focus.is_none()
                && c.config.blurs_at(it)
        });
        if estimate {
            let found = self.estimate_focus()?;
            if let Some(c) = self.coc.as_mut() {
                c.config.initial_focus = Some(found);
            }
        }
        let refocus = self
            .coc
            .as_ref()
            .is_some_and(|c| c.focus.is_some() && c.config.refocuses_at(it));
        if refocus {
            self.refocus()?;
        }
        let densify = d.as_ref().filter(|_| plan.densify);
        let on_gpu = self.densifies_on_gpu(self.num_gaussians());
        // INRIA's order: densify, (Deblurring 3DGS) add points, reset opacities.
        let adds_points = d.as_ref().is_some_and(|d| d.adds_points_at(it));
        let reset_in_step = plan.reset_opacity && !adds_points && (on_gpu || !plan.densify);
        let mut batch = self.batch.take().ok_or(TrainError::Poisoned)?;
        let mut band_count = 1;
        let result = self
            .aim(&mut batch, self.cameras[view], background)
            .and_then(|()| {
                let mut rec = self.ctx.recorder();
                let camera = self.cameras[view];
                let limit = self.frame_binding_limit();
                if self.config.coc.as_ref().is_some_and(|c| c.blurs_at(it)) {
                    self.optimise_coc(&mut rec, &batch, view, it, plan, background, &mut watch)?;
                } else if let Some(bands) =
                    bands::plan(camera.width, camera.height, limit).map_err(TrainError::Invalid)?
                {
                    self.optimise_banded(&mut rec, &mut batch, view, it, plan, &bands, &mut watch)?;
                    band_count = bands.len() as u32;
                } else {
                    self.optimise(&mut rec, &batch, view, it, plan, &mut watch)?;
                }
                if let Some(d) = densify.filter(|_| on_gpu) {
                    self.densify_on_gpu(&mut rec, &mut batch.params, d, it)?;
                }
                if reset_in_step {
                    self.record_opacity_reset(&mut rec, &batch.params);
                }
                rec.submit();
                self.readback.start();
                Ok(())
            });
        self.batch = Some(batch);
        result?;
        if let Some(d) = densify.filter(|_| !on_gpu) {
            let before = self.num_gaussians();
            self.densify_on_cpu(d, it)?;
            self.grow_capacity_with(before);
        }
        if let Some(d) = d.as_ref().filter(|d| d.adds_points_at(it)) {
            let before = self.num_gaussians();
            self.add_points(d, it)?;
            self.grow_capacity_with(before);
        }
        if plan.reset_opacity && !reset_in_step {
            self.reset_opacity()?;
        }
        watch.times.density += watch.lap(self.ctx)?;
        self.iteration = it;
        Ok(StepStats {
            iteration: it,
            view,
            sh_degree: self.sh_degree(),
            num_gaussians: self.num_gaussians(),
            readings,
            phases: watch.result(),
            bands: band_count,
        })
    }

    /// Points the single-image batch at `camera` over `background`, all Gaussians.
    fn aim(
        &self,
        batch: &mut Batch,
        camera: Camera,
        background: [f32; 3],
    ) -> Result<(), TrainError> {
        let spec = ImageSpec {
            camera,
            background,
            first: 0,
            count: batch.params.num_gaussians,
            crop: None,
        };
        Ok(batch.set_images(self.ctx, vec![spec])?)
    }

    /// Turns finished read-backs into readings; an overflowed step grows the intersection
    /// room and queues its view again.
    fn absorb(&mut self, done: Vec<(Pending, Vec<u8>)>) -> Result<Vec<Reading>, TrainError> {
        let mut readings = Vec::new();
        for (pending, bytes) in done {
            let words: Vec<u32> = bytes
                .chunks_exact(4)
                .map(|w| u32::from_le_bytes([w[0], w[1], w[2], w[3]]))
                .collect();
            let step = match pending {
                Pending::Step(step) => step,
                Pending::Count => {
                    let mut batch = self.batch.take().ok_or(TrainError::Poisoned)?;
                    let result = self.apply_count(&mut batch.params, &words);
                    self.batch = Some(batch);
                    result?;
                    continue;
                }
            };
            let word = |i: usize| words.get(i).copied().unwrap_or(0);
            let (overflowed, needed) = (word(0) != 0, word(1));
            self.note_intersections(needed);
            if overflowed {
                let most = self.most_intersections();
                if needed > most {
                    // Retrying would overflow forever.
                    return Err(
                        cocog_engine::EngineError::TooManyIntersections { needed, most }.into(),
                    );
                }
                self.redo.push_back(step.view);
                continue;
            }
            if let Some(loss) = step.loss {
                let value = loss.value_from(&bytes[8..]);
                readings.push(Reading {
                    iteration: step.iteration,
                    view: step.view,
                    num_gaussians: step.num_gaussians,
                    sh_degree: step.sh_degree,
                    loss: value.loss,
                    psnr: value.psnr,
                });
            }
        }
        Ok(readings)
    }

    /// The fixed background, or with `random_background` a colour drawn per iteration from
    /// the seed and the iteration alone (so a resumed run draws the same ones).
    fn background_at(&self, it: u32) -> [f32; 3] {
        if !self.config.random_background {
            return self.config.background;
        }
        let mut rng = SplitMix64::new(self.config.seed ^ 0xB6C0_0000_0000_0000 ^ u64::from(it));
        std::array::from_fn(|_| rng.next_f64() as f32)
    }

    /// Renders the current Gaussians from `camera` over the configured background, in bands
    /// of rows where the frame outgrows a buffer binding.
    pub fn render(&mut self, camera: &Camera) -> Result<RenderedImage, TrainError> {
        let mut batch = self.batch.take().ok_or(TrainError::Poisoned)?;
        let spec = ImageSpec {
            camera: *camera,
            background: self.config.background,
            first: 0,
            count: batch.params.num_gaussians,
            crop: None,
        };
        let result = self.renderer.render_frame(self.ctx, &mut batch, spec);
        self.batch = Some(batch);
        Ok(result?.image)
    }

    /// Reads the current Gaussians back to the CPU (one sync per parameter buffer).
    pub fn gaussians(&self) -> Result<GaussianParams, TrainError> {
        let p = self.params()?;
        let n = self.exact_count()?;
        // The gradient readback reads any buffers shaped like the parameters.
        let g = p.read_grads(self.ctx, 0, n)?;
        Ok(GaussianParams {
            sh_degree: p.sh_degree,
            means: g.v_means,
            log_scales: g.v_log_scales,
            quats: g.v_quats,
            opacity_logits: g.v_opacity_logits,
            sh: g.v_sh,
        })
    }

    /// Records forward, loss, backward, statistics and Adam for `view` into `rec`, and the
    /// step's read-back (status words, plus the loss partials on logging iterations).
    fn optimise(
        &mut self,
        rec: &mut Recorder<'c>,
        batch: &Batch,
        view: usize,
        it: u32,
        plan: Plan,
        watch: &mut Stopwatch,
    ) -> Result<(), TrainError> {
        let c = &self.config;
        let ws = &mut self.ws;
        let state = self.renderer.encode_forward(rec, ws, batch, self.capacity);
        let (w, h) = (batch.width(), batch.height());
        let target = &self.targets[view];
        let out = self
            .loss
            .compute(rec, ws, &state.rgba, target, w, h, 1, c.lambda_dssim)?;
        watch.times.forward += watch.lap_recorded(rec)?;
        let grads = self
            .renderer
            .encode_backward(rec, ws, batch, &state, &out.v_pred, None);
        watch.times.backward += watch.lap_recorded(rec)?;
        if plan.gather_stats {
            self.stats.accumulate(rec, &state, &grads, w, h);
        }
        watch.times.density += watch.lap_recorded(rec)?;
        self.record_readings(rec, &state.status, &out, view, it, &batch.params)?;
        // INRIA densifies before `optimizer.step()`, and the parameters it replaces have no
        // gradient, so torch skips them: no step at all when densifying, and none for the
        // opacities when resetting them.
        if plan.densify {
            return Ok(());
        }
        let g = &grads.params;
        let v = [&g.means, &g.log_scales, &g.quats, &g.opacity_logits, &g.sh].map(|b| &b.buffer);
        self.step_base(rec, &batch.params, v, it, plan, &state.status);
        watch.times.optimizer += watch.lap_recorded(rec)?;
        Ok(())
    }

    /// Records the step's read-back: the renderer's status words, and on logging iterations
    /// the loss partials.
    fn record_readings(
        &mut self,
        rec: &mut Recorder<'c>,
        status: &GpuBuffer,
        out: &LossOutput,
        view: usize,
        it: u32,
        params: &ParamBuffers,
    ) -> Result<(), TrainError> {
        let c = &self.config;
        let logged = c.loss_every > 0 && it.is_multiple_of(c.loss_every);
        let mut ranges = vec![(&status.buffer, 0, 8)];
        if logged {
            ranges.push((&out.partials.buffer, 0, out.partials_bytes()));
        }
        let tag = InFlight {
            iteration: it,
            view,
            num_gaussians: params.num_gaussians,
            sh_degree: params.sh_degree,
            loss: logged.then(|| out.clone()),
        };
        Ok(self.readback.record(rec, &ranges, Pending::Step(tag))?)
    }

    /// Adam on the base Gaussians with gradients `v` (means, log-scales, rotations,
    /// opacities, SH); a no-op on the GPU when `status` says the step overflowed.
    fn step_base(
        &self,
        rec: &mut Recorder<'c>,
        p: &ParamBuffers,
        v: [&wgpu::Buffer; 5],
        it: u32,
        plan: Plan,
        status: &GpuBuffer,
    ) {
        let (c, m) = (&self.config, &self.moments);
        let lr = AdamConfig::with_lr;
        let groups = [
            (
                &p.means,
                v[0],
                &m.means,
                c.position_lr(it, self.scene_scale),
            ),
            (&p.log_scales, v[1], &m.log_scales, c.scaling_lr),
            (&p.quats, v[2], &m.quats, c.rotation_lr),
            (&p.opacity_logits, v[3], &m.opacity_logits, c.opacity_lr),
        ];
        // Adam's step count, restarted where the point addition rebuilt the moments: counted
        // from iteration 1 instead, the bias correction is already ~1 over zeroed moments,
        // and the first hundred updates after the rebuild come out 3–6× the rebuilt
        // optimizer's.
        let t = it.saturating_sub(self.adam_origin).max(1);
        let skip = Some(&status.buffer);
        let reset_skips = if plan.reset_opacity { 3 } else { groups.len() };
        for (k, (param, grad, moments, rate)) in groups.into_iter().enumerate() {
            if k == reset_skips {
                continue;
            }
            self.adam
                .encode(rec, param, grad, moments, &lr(rate), t, skip);
        }
        let coeffs = sh_coeffs_per_channel(p.sh_degree) as u32;
        let sh_lr = lr(c.feature_lr).interleaved(coeffs, c.feature_rest_lr());
        self.adam.encode(rec, &p.sh, v[4], &m.sh, &sh_lr, t, skip);
    }
}

/// The optimisation state a trainer starts from: fresh in `new`, a checkpoint in `resume`.
pub(super) struct Resumed {
    params: ParamBuffers,
    moments: Moments,
    stats: GradStats,
    rng: SplitMix64,
    order: ViewOrder,
    iteration: u32,
    /// The point addition's iteration once it has run (0 before): the released code rebuilds
    /// its optimizer there, so the Gaussians' Adam bias correction starts again after it.
    adam_origin: u32,
    /// CoCoGaussian's lens model, when resuming a run that has one.
    coc: Option<crate::CocCheckpoint>,
}

/// The training cameras' mean centre and viewing direction.
fn depth_axis(cameras: &[Camera]) -> crate::DepthAxis {
    let centres: Vec<[f64; 3]> = cameras.iter().map(Camera::centre).collect();
    let forwards: Vec<[f64; 3]> = cameras
        .iter()
        .map(|c| {
            let m = &c.world_from_camera;
            [m[0][2], m[1][2], m[2][2]]
        })
        .collect();
    crate::DepthAxis::from_cameras(&centres, &forwards)
}

/// Views share one resolution and match their images; the Gaussians fit the SH limit.
fn check_inputs(
    init: &GaussianParams,
    views: &[TrainView],
    config: &TrainConfig,
) -> Result<(), TrainError> {
    let first = views
        .first()
        .ok_or_else(|| TrainError::Invalid("no training views".into()))?;
    let (w, h) = (first.camera.width, first.camera.height);
    for (i, v) in views.iter().enumerate() {
        if (v.camera.width, v.camera.height) != (w, h) {
            return Err(TrainError::Invalid(format!(
                "view {i} is {}×{}, view 0 is {w}×{h}",
                v.camera.width, v.camera.height
            )));
        }
        if v.image.len() != (w * h) as usize {
            return Err(TrainError::Invalid(format!(
                "view {i} has {} pixels, its camera {}",
                v.image.len(),
                w * h
            )));
        }
    }
    if config.max_sh_degree > MAX_SH_DEGREE || init.sh_degree > config.max_sh_degree {
        return Err(TrainError::Invalid(format!(
            "SH degree {} / max {} (engine max {MAX_SH_DEGREE})",
            init.sh_degree, config.max_sh_degree
        )));
    }
    if init.is_empty() {
        return Err(TrainError::Invalid("no Gaussians to train".into()));
    }
    Ok(())
}

/// What an iteration does besides the optimiser step (INRIA's schedule, see `DensifyConfig`).
#[derive(Clone, Copy, Debug)]
struct Plan {
    gather_stats: bool,
    densify: bool,
    reset_opacity: bool,
}
