//! The trainer's side of adaptive density control: densification on the GPU in the step's
//! own recorder (`GpuDensify`), the CPU rule (`plan_densify`) where the doubled set would not
//! fit a binding, point addition and opacity resets.

use cocog_engine::{
    AdamMoments, GpuBuffer, GpuContext, Kernel, ParamBuffers, Recorder, sh_coeffs_per_channel,
    shader,
};

use super::{Moments, Pending, PendingCount, Trainer};
use crate::{
    DensifyConfig, DensifyInputs, Origin, SplitNoise, TrainError, apply_plan, gather_rows,
    inverse_sigmoid, plan_densify,
};

/// INRIA `reset_opacity` clamps every opacity to at most this.
const RESET_OPACITY: f32 = 0.01;

/// Moments of one group rearranged like the Gaussians; new ones start at zero, as INRIA's
/// `cat_tensors_to_optimizer` does.
fn regather(
    ctx: &GpuContext,
    old: &AdamMoments,
    stride: usize,
    origins: &[Origin],
) -> Result<AdamMoments, TrainError> {
    let len = old.len as usize;
    let m: Vec<f32> = ctx.read(&old.m, len)?;
    let v: Vec<f32> = ctx.read(&old.v, len)?;
    let (m, v) = (
        gather_rows(&m, stride, origins, true),
        gather_rows(&v, stride, origins, true),
    );
    Ok(AdamMoments {
        len: m.len() as u32,
        m: ctx.storage_from("adam m", &m),
        v: ctx.storage_from("adam v", &v),
    })
}

impl<'c> Trainer<'c> {
    /// Whether densifying `n` Gaussians can run on the GPU: every group must hold 2n rows
    /// within a buffer binding. Otherwise `densify_on_cpu` does it.
    /// Also where 2n would pass the run's cap: the CPU path holds the set to it.
    pub(super) fn densifies_on_gpu(&self, n: u32) -> bool {
        let limit = self.ctx.binding_limit();
        !self.cpu_densification
            && 2 * u64::from(n) <= u64::from(self.most)
            && fits(u64::from(2 * n), self.sh_stride(), limit)
    }

    /// Floats of SH per Gaussian.
    pub(super) fn sh_stride(&self) -> u32 {
        3 * sh_coeffs_per_channel(self.sh_degree()) as u32
    }

    /// INRIA `densify_and_prune` at iteration `it`, recorded into the step's `rec` after its
    /// statistics: no read-back and no submission. Until the new count comes back with a
    /// later step's read-back (`apply_count`), steps train all 2n rows; those past the count
    /// are buried and change nothing. Statistics restart from zero.
    pub(super) fn densify_on_gpu(
        &mut self,
        rec: &mut Recorder<'c>,
        params: &mut ParamBuffers,
        config: &DensifyConfig,
        it: u32,
    ) -> Result<(), TrainError> {
        self.settle_count(params)?;
        let n = params.num_gaussians;
        // `self.sh_degree()` is unknown while the step holds the parameters.
        let sh = 3 * sh_coeffs_per_channel(params.sh_degree) as u32;
        self.reserve_rows(rec, params, 2 * n, sh);
        let m = &self.moments;
        let moments: [(&GpuBuffer, u32); 10] = [
            (&m.means.m, 3),
            (&m.means.v, 3),
            (&m.log_scales.m, 3),
            (&m.log_scales.v, 3),
            (&m.quats.m, 4),
            (&m.quats.v, 4),
            (&m.opacity_logits.m, 1),
            (&m.opacity_logits.v, 1),
            (&m.sh.m, sh),
            (&m.sh.v, sh),
        ];
        let (accum, denom) = self.stats.buffers();
        let inputs = DensifyInputs {
            config,
            scale: self.scene_scale,
            prune_large: config.prunes_large_at(it),
            noise: SplitNoise {
                seed: self.config.seed,
                iteration: it,
            },
            axis: &self.depth_axis,
            accum,
            denom,
            moments: &moments,
        };
        let recorded = self.densify.record(rec, &mut self.ws, params, &inputs);
        self.readback
            .record(rec, &[(&recorded.counts, 0, 16)], Pending::Count)?;
        self.pending_count = Some(PendingCount {
            counts: recorded.counts,
            before: n,
        });
        self.set_count(params, 2 * n);
        self.stats.restart(rec, 2 * n);
        Ok(())
    }

    /// Takes the count a densification left (words: after, kept, cloned, split) once it
    /// arrived.
    pub(super) fn apply_count(
        &mut self,
        params: &mut ParamBuffers,
        words: &[u32],
    ) -> Result<(), TrainError> {
        let Some(pending) = self.pending_count.take() else {
            return Ok(());
        };
        let after = words.first().copied().unwrap_or(0);
        if after == 0 {
            return Err(TrainError::Invalid(
                "densification pruned every Gaussian".into(),
            ));
        }
        self.set_count(params, after);
        self.stats.truncate(after);
        self.grow_capacity_with(pending.before);
        Ok(())
    }

    /// Waits for a densification's count still on its way (outside a step's hot path:
    /// checkpoints, point addition, SH growth, a second densification within a few steps).
    pub(super) fn settle_count(&mut self, params: &mut ParamBuffers) -> Result<(), TrainError> {
        if let Some(p) = &self.pending_count {
            let words: Vec<u32> = self.ctx.read(&p.counts, 4)?;
            self.apply_count(params, &words)?;
        }
        Ok(())
    }

    /// The Gaussians without the buried rows of a densification whose count is still on its
    /// way (read now if so).
    pub(super) fn exact_count(&self) -> Result<u32, TrainError> {
        match &self.pending_count {
            Some(p) => Ok(self.ctx.read::<u32>(&p.counts, 1)?[0]),
            None => Ok(self.num_gaussians()),
        }
    }

    /// `settle_count` on the trainer's own parameters.
    pub(super) fn settle(&mut self) -> Result<(), TrainError> {
        let mut batch = self.batch.take().ok_or(TrainError::Poisoned)?;
        let result = self.settle_count(&mut batch.params);
        self.batch = Some(batch);
        result
    }

    fn set_count(&mut self, params: &mut ParamBuffers, n: u32) {
        params.num_gaussians = n;
        let sh = 3 * sh_coeffs_per_channel(params.sh_degree) as u32;
        self.moments.set_count(n, sh);
    }

    /// Room for `rows` Gaussians in every parameter group, Adam moment and statistic; a buffer
    /// short of it grows to a quarter beyond (copies recorded in `rec`, before the kernels that
    /// read them). Groups are checked one by one: SH growth re-lays the SH buffers exactly.
    fn reserve_rows(&mut self, rec: &mut Recorder<'c>, p: &mut ParamBuffers, rows: u32, sh: u32) {
        let n = p.num_gaussians;
        let limit = self.ctx.binding_limit();
        let mut grown = u64::from(rows) + u64::from(rows) / 4;
        if !fits(grown, sh, limit) {
            grown = u64::from(rows);
        }
        let grown = grown as u32;
        let ctx = self.ctx;
        for (buffer, stride) in [
            (&mut p.means, 3),
            (&mut p.log_scales, 3),
            (&mut p.quats, 4),
            (&mut p.opacity_logits, 1),
            (&mut p.sh, sh),
        ] {
            grow(rec, ctx, buffer, [n, rows, grown], stride);
        }
        let m = &mut self.moments;
        for (moments, stride) in [
            (&mut m.means, 3),
            (&mut m.log_scales, 3),
            (&mut m.quats, 4),
            (&mut m.opacity_logits, 1),
            (&mut m.sh, sh),
        ] {
            grow(rec, ctx, &mut moments.m, [n, rows, grown], stride);
            grow(rec, ctx, &mut moments.v, [n, rows, grown], stride);
        }
        self.stats.reserve(rec, rows, grown);
    }

    /// The CPU reference of `densify_and_prune`: read back, `plan_densify`, upload again.
    pub(super) fn densify_on_cpu(
        &mut self,
        config: &DensifyConfig,
        it: u32,
    ) -> Result<(), TrainError> {
        self.settle()?;
        let ctx = self.ctx;
        let g = self.gaussians()?;
        let grads = self.stats.read_mean(ctx)?;
        let noise = SplitNoise {
            seed: self.config.seed,
            iteration: it,
        };
        let plan_with = |config: &DensifyConfig| {
            plan_densify(
                &g,
                &grads,
                self.scene_scale,
                config.prunes_large_at(it),
                config,
                &noise,
                Some(&self.depth_axis),
            )
        };
        let mut plan = plan_with(config);
        if plan.origins.len() > self.most as usize {
            // At the cap: prune as usual, but neither clone nor split.
            plan = plan_with(&DensifyConfig {
                grad_threshold: f32::INFINITY,
                ..config.clone()
            });
            self.capped = Some(self.most);
        }
        if plan.origins.is_empty() {
            return Err(TrainError::Invalid(format!(
                "densification at iteration {it} pruned every Gaussian"
            )));
        }
        let dense = apply_plan(&g, &plan);
        let o = &plan.origins;
        let m = &self.moments;
        let moments = Moments {
            means: regather(ctx, &m.means, 3, o)?,
            log_scales: regather(ctx, &m.log_scales, 3, o)?,
            quats: regather(ctx, &m.quats, 4, o)?,
            opacity_logits: regather(ctx, &m.opacity_logits, 1, o)?,
            sh: regather(ctx, &m.sh, g.sh_stride(), o)?,
        };
        let params = ParamBuffers::upload(ctx, &[&dense])?;
        self.stats.reset(ctx, params.num_gaussians);
        self.moments = moments;
        *self.params_mut()? = params;
        Ok(())
    }

    /// Deblurring 3DGS's point addition (method.md §8.1): new Gaussians, every shape
    /// re-initialised, Gaussian Adam moments, step count and statistics restarted after `it`:
    /// the released code rebuilds its optimizer here. h_θ, F and the focus distances keep
    /// their moments: that they restart there is a side effect of one optimizer holding
    /// everything. Returns how many points were added.
    pub(super) fn add_points(
        &mut self,
        config: &DensifyConfig,
        it: u32,
    ) -> Result<usize, TrainError> {
        self.settle()?;
        let ctx = self.ctx;
        let g = self.gaussians()?;
        let room = (self.most as usize).saturating_sub(g.len());
        if room < config.add_points_count as usize {
            self.capped = Some(self.most);
        }
        let (dense, added) = crate::add_points(
            &g,
            room.min(config.add_points_count as usize),
            f64::from(config.add_points_distance),
            &mut self.rng,
        );
        let params = ParamBuffers::upload(ctx, &[&dense])?;
        self.stats.reset(ctx, params.num_gaussians);
        self.moments = Moments::new(ctx, &params);
        self.adam_origin = it;
        *self.params_mut()? = params;
        Ok(added)
    }

    /// INRIA `reset_opacity` in its own submission, queued behind this iteration's step.
    pub(super) fn reset_opacity(&mut self) -> Result<(), TrainError> {
        let mut rec = self.ctx.recorder();
        self.record_opacity_reset(&mut rec, self.params()?);
        rec.submit();
        Ok(())
    }

    /// Records INRIA `reset_opacity`: opacity ≤ 0.01 everywhere (buried rows stay buried),
    /// and fresh Adam moments for it.
    pub(super) fn record_opacity_reset(&self, rec: &mut Recorder, params: &ParamBuffers) {
        let n = params.num_gaussians;
        let cap = rec.uniform(&ResetParams {
            n,
            cap: inverse_sigmoid(RESET_OPACITY),
            pad: [0; 2],
        });
        self.opacity_reset.dispatch_1d(
            rec,
            &[(0, &cap), (1, &params.opacity_logits)],
            n.div_ceil(256),
        );
        let m = &self.moments.opacity_logits;
        rec.encoder().clear_buffer(&m.m, 0, None);
        rec.encoder().clear_buffer(&m.v, 0, None);
    }
}

/// Whether `rows` rows of the widest group (SH, or the 4-float rotations) fit `limit` bytes.
fn fits(rows: u64, sh: u32, limit: u64) -> bool {
    rows * u64::from(sh.max(4)) * 4 <= limit
}

/// Unless `buffer` holds `needed` rows of `stride` floats, replaces it by one of `grown` rows
/// holding its first `live` rows.
fn grow(
    rec: &mut Recorder,
    ctx: &GpuContext,
    buffer: &mut GpuBuffer,
    [live, needed, grown]: [u32; 3],
    stride: u32,
) {
    let row = u64::from(stride) * 4;
    if buffer.size() >= u64::from(needed) * row {
        return;
    }
    let grown = ctx.storage("gaussian rows", u64::from(grown) * row);
    let live = u64::from(live) * u64::from(stride) * 4;
    if live > 0 {
        rec.encoder()
            .copy_buffer_to_buffer(buffer, 0, &grown, 0, live);
    }
    *buffer = grown;
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct ResetParams {
    n: u32,
    cap: f32,
    pad: [u32; 2],
}

/// The kernel `reset_opacity` runs.
pub(super) fn opacity_reset_kernel(ctx: &GpuContext) -> Kernel {
    let module = shader(ctx, "opacity_reset", include_str!("opacity_reset.wgsl"));
    Kernel::new(ctx, &module, "reset_opacity")
}
