//! Checkpoints: the trainer's GPU state read back into a `TrainState`, and rebuilt from one.

use cocog_engine::{AdamMoments, GpuContext, ParamBuffers};

use super::{Moments, Resumed, Trainer, check_inputs};
use crate::{
    GradStats, MomentState, SplitMix64, TrainConfig, TrainError, TrainState, TrainView, ViewOrder,
};

/// The first `rows` Gaussians' moments (`stride` floats each).
fn read_moments(
    ctx: &GpuContext,
    m: &AdamMoments,
    rows: u32,
    stride: u32,
) -> Result<MomentState, TrainError> {
    let len = (rows * stride).min(m.len) as usize;
    Ok(MomentState {
        m: ctx.read(&m.m, len)?,
        v: ctx.read(&m.v, len)?,
    })
}

fn upload_moments(ctx: &GpuContext, s: &MomentState) -> AdamMoments {
    AdamMoments {
        len: s.m.len() as u32,
        m: ctx.storage_from("adam m", &s.m),
        v: ctx.storage_from("adam v", &s.v),
    }
}

impl<'c> Trainer<'c> {
    /// Reads the whole optimisation state back (one sync per buffer), without the buried rows
    /// of a densification whose count is on its way; `downscale` is recorded so a resume can
    /// refuse a different image size.
    pub fn snapshot(&self, downscale: u32) -> Result<TrainState, TrainError> {
        let ctx = self.ctx;
        let m = &self.moments;
        let n = self.exact_count()?;
        let sh = self.sh_stride();
        let (grad_accum, grad_denom) = self.stats.read_raw(ctx, n)?;
        let (order_rng, stack) = self.order.state();
        Ok(TrainState {
            iteration: self.iteration,
            adam_origin: Some(self.adam_origin),
            views: self.targets.len() as u32,
            downscale,
            params: self.gaussians()?,
            moments: [
                read_moments(ctx, &m.means, n, 3)?,
                read_moments(ctx, &m.log_scales, n, 3)?,
                read_moments(ctx, &m.quats, n, 4)?,
                read_moments(ctx, &m.opacity_logits, n, 1)?,
                read_moments(ctx, &m.sh, n, sh)?,
            ],
            grad_accum,
            grad_denom,
            rng: self.rng.state(),
            order_rng,
            order_stack: stack.iter().map(|&v| v as u32).collect(),
            coc: match &self.coc {
                Some(c) => Some(c.checkpoint(ctx, self.cameras.len())?),
                None => None,
            },
        })
    }

    /// Continues a run from `state` on the same views: the next `step` is iteration
    /// `state.iteration + 1` and behaves as it would have without the interruption.
    pub fn resume(
        ctx: &'c GpuContext,
        state: &TrainState,
        views: &[TrainView],
        config: TrainConfig,
    ) -> Result<Self, TrainError> {
        check_inputs(&state.params, views, &config)?;
        if state.views as usize != views.len() {
            return Err(TrainError::Invalid(format!(
                "the checkpoint was trained on {} views, this run has {}",
                state.views,
                views.len()
            )));
        }
        if let Some(&bad) = state
            .order_stack
            .iter()
            .find(|&&v| v as usize >= views.len())
        {
            return Err(TrainError::Invalid(format!(
                "the checkpoint's view order names view {bad} of {}",
                views.len()
            )));
        }
        let params = ParamBuffers::upload(ctx, &[&state.params])?;
        let [means, log_scales, quats, opacity_logits, sh] = &state.moments;
        let resumed = Resumed {
            moments: Moments {
                means: upload_moments(ctx, means),
                log_scales: upload_moments(ctx, log_scales),
                quats: upload_moments(ctx, quats),
                opacity_logits: upload_moments(ctx, opacity_logits),
                sh: upload_moments(ctx, sh),
            },
            stats: GradStats::from_raw(ctx, &state.grad_accum, &state.grad_denom),
            rng: SplitMix64::new(state.rng),
            order: ViewOrder::resume(
                views.len(),
                state.order_rng,
                state.order_stack.iter().map(|&v| v as usize).collect(),
            ),
            iteration: state.iteration,
            // Older checkpoints: the addition happened if the schedule's iteration is past.
            adam_origin: state.adam_origin.unwrap_or_else(|| {
                config
                    .densify
                    .as_ref()
                    .map(|d| d.add_points_at)
                    .filter(|&at| at > 0 && at <= state.iteration)
                    .unwrap_or(0)
            }),
            params,
            coc: state.coc.clone(),
        };
        Self::assemble(ctx, views, config, resumed)
    }
}
