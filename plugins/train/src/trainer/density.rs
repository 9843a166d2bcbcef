//! The trainer's side of adaptive density control: read back, decide on the CPU
//! (`plan_densify`), re-upload parameters and Adam moments in the new order.

use cocog_engine::{AdamMoments, GpuContext, Kernel, ParamBuffers, shader};

use super::{Moments, Trainer};
use crate::{
    DensifyConfig, DensifyPlan, Origin, TrainError, apply_plan, gather_rows, inverse_sigmoid,
    plan_densify,
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

impl Trainer<'_> {
    /// INRIA `densify_and_prune` at iteration `it`; statistics restart from zero afterwards.
    pub(super) fn densify_and_prune(
        &mut self,
        config: &DensifyConfig,
        it: u32,
    ) -> Result<DensifyPlan, TrainError> {
        let ctx = self.ctx;
        let g = self.gaussians()?;
        let grads = self.stats.read_mean(ctx)?;
        let prune_large = config.prunes_large_at(it);
        let plan = plan_densify(
            &g,
            &grads,
            self.scene_scale,
            prune_large,
            config,
            &mut self.rng,
            Some(&self.depth_axis),
        );
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
        Ok(plan)
    }

    /// Deblurring 3DGS's point addition (method.md §8.1): new Gaussians, every shape
    /// re-initialised, Gaussian Adam moments and statistics restarted (the released code
    /// rebuilds its optimizer here). h_θ, F and the focus distances keep their moments: that
    /// they restart there is a side effect of one optimizer holding everything. Returns how
    /// many points were added.
    pub(super) fn add_points(&mut self, config: &DensifyConfig) -> Result<usize, TrainError> {
        let ctx = self.ctx;
        let g = self.gaussians()?;
        let (dense, added) = crate::add_points(
            &g,
            config.add_points_count as usize,
            f64::from(config.add_points_distance),
            &mut self.rng,
        );
        let params = ParamBuffers::upload(ctx, &[&dense])?;
        self.stats.reset(ctx, params.num_gaussians);
        self.moments = Moments::new(ctx, &params);
        *self.params_mut()? = params;
        Ok(added)
    }

    /// INRIA `reset_opacity`: opacity ≤ 0.01 everywhere, and fresh Adam moments for it, on
    /// the GPU (queued behind this iteration's step).
    pub(super) fn reset_opacity(&mut self) -> Result<(), TrainError> {
        let ctx = self.ctx;
        let params = self.params()?;
        let n = params.num_gaussians;
        let mut rec = ctx.recorder();
        let cap = rec.uniform(&ResetParams {
            n,
            cap: inverse_sigmoid(RESET_OPACITY),
            pad: [0; 2],
        });
        self.opacity_reset.dispatch_1d(
            &mut rec,
            &[(0, &cap), (1, &params.opacity_logits)],
            n.div_ceil(256),
        );
        let m = &self.moments.opacity_logits;
        rec.encoder().clear_buffer(&m.m, 0, None);
        rec.encoder().clear_buffer(&m.v, 0, None);
        rec.submit();
        Ok(())
    }
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
