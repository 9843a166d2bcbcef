//! One blurred CoCoGaussian iteration (method.md §2): h_θ expands the base Gaussians into
//! M + 1 sets, one launch renders them, F (or the mean, before F starts) composites them, and
//! the loss against the defocused photo flows back through F's product, the rasterizer and the
//! expansion's adjoint into the base Gaussians, h_θ, F and the view's focus distance.

use cocog_engine::coc::CocVariant;
use cocog_engine::nn::CompositeMode;
use cocog_engine::{AdamConfig, Batch, Recorder, sh_coeffs_per_channel};

use super::coc::CocState;
use super::{Plan, Stopwatch, Trainer};
use crate::TrainError;

impl<'c> Trainer<'c> {
    pub(super) fn optimise_coc(
        &mut self,
        rec: &mut Recorder<'c>,
        batch: &Batch,
        view: usize,
        it: u32,
        plan: Plan,
        background: [f32; 3],
        watch: &mut Stopwatch,
    ) -> Result<(), TrainError> {
        let ctx = self.ctx;
        if self.coc.as_ref().is_some_and(|c| c.focus.is_none()) {
            let means: Vec<[f32; 3]> =
                ctx.read(&batch.params.means, batch.params.num_gaussians as usize)?;
            let cameras = self.cameras.clone();
            if let Some(coc) = self.coc.as_mut() {
                coc.init_focus(ctx, &means, &cameras);
                // From now on a step renders M + 1 copies of every Gaussian: the intersection
                // counts that come back would say so only after a few overflowed steps.
                let room = self.capacity.saturating_mul(coc.sets());
                self.set_room(room);
            }
        }
        let coc = self.coc.as_mut().ok_or(TrainError::Poisoned)?;
        let ws = &mut self.ws;
        let base = &batch.params;
        let n = base.num_gaussians;
        let sets = coc.sets();
        let camera = self.cameras[view];
        let step = coc.step_for(view, &camera)?;
        let focus = coc.focus.as_ref().ok_or(TrainError::Poisoned)?;
        let exp = coc.kernels.encode_forward(
            rec,
            ws,
            &coc.weights,
            &base.means,
            &base.log_scales,
            &base.quats,
            &focus.values,
            &focus.apertures,
            n,
            &step,
        );
        watch.times.coc_net += watch.lap_recorded(rec)?;
        let set_params = coc.kernels.sets(base, &exp);
        let sbatch = CocState::aim(&mut coc.batch, ctx, set_params, sets, camera, background)?;
        let state = self.renderer.encode_forward(rec, ws, sbatch, self.capacity);
        watch.times.forward += watch.lap_recorded(rec)?;
        let (w, h) = (sbatch.width(), sbatch.height());
        let composites = coc.config.composites_at(it);
        let mode = if composites {
            CompositeMode::Learned
        } else {
            CompositeMode::Uniform
        };
        let comp =
            coc.compositor
                .encode_forward(rec, ws, &coc.f_params, &state.rgba, w, h, sets, mode);
        watch.times.compositor += watch.lap_recorded(rec)?;
        let out = self.loss.compute(
            rec,
            ws,
            &comp.blend,
            &self.targets[view],
            w,
            h,
            1,
            self.config.lambda_dssim,
        )?;
        watch.times.forward += watch.lap_recorded(rec)?;
        let back =
            coc.compositor
                .encode_backward(rec, ws, &coc.f_params, &state.rgba, &comp, &out.v_pred);
        watch.times.compositor += watch.lap_recorded(rec)?;
        let grads = self
            .renderer
            .encode_backward(rec, ws, sbatch, &state, &back.v_renders, None);
        watch.times.backward += watch.lap_recorded(rec)?;
        let g = &grads.params;
        let cg = coc.kernels.encode_backward(
            rec,
            ws,
            &coc.weights,
            &base.quats,
            &exp,
            &g.means,
            &g.log_scales,
            &g.quats,
            self.cameras.len() as u32,
            &step,
        );
        let v_opacity = ws.buffer(ctx, "coc v opacities", u64::from(n) * 4);
        let stride = 3 * sh_coeffs_per_channel(base.sh_degree) as u64;
        let v_sh = ws.buffer(ctx, "coc v sh", u64::from(n) * stride * 4);
        coc.kernels
            .encode_sum_sets(rec, &g.opacity_logits, &v_opacity, n);
        coc.kernels
            .encode_sum_sets(rec, &g.sh, &v_sh, n * stride as u32);
        watch.times.coc_net += watch.lap_recorded(rec)?;
        if plan.gather_stats {
            self.stats.accumulate_sets(rec, &state, &grads, w, h, sets);
        }
        watch.times.density += watch.lap_recorded(rec)?;

        // h_θ, F and the focus distances: Adam counts their steps from when each joined.
        let coc = self.coc.as_ref().ok_or(TrainError::Poisoned)?;
        let skip = Some(&state.status.buffer);
        let lr = AdamConfig::with_lr(coc.config.kernel_lr(it, self.config.iterations));
        let since = |start: u32| it.saturating_sub(start) + 1;
        let t_blur = since(coc.config.blur_start);
        self.adam.encode(
            rec,
            &coc.weights,
            &cg.v_weights,
            &coc.weights_m,
            &lr,
            t_blur,
            skip,
        );
        if let Some(f) = &coc.focus {
            self.adam
                .encode(rec, &f.values, &cg.v_focus, &f.moments, &lr, t_blur, skip);
            if coc.config.net.variant == CocVariant::Lens {
                let a = &f.apertures;
                let (g, m) = (&cg.v_aperture, &f.aperture_moments);
                self.adam.encode(rec, a, g, m, &lr, t_blur, skip);
            }
        }
        if composites {
            let t = since(coc.config.composite_start.max(coc.config.blur_start));
            self.adam
                .encode(rec, &coc.f_params, &back.v_params, &coc.f_m, &lr, t, skip);
        }
        let status = state.status.clone();
        self.record_readings(rec, &status, &out, view, it, &batch.params)?;
        if plan.densify {
            return Ok(());
        }
        let v = [
            &cg.v_means,
            &cg.v_log_scales,
            &cg.v_quats,
            &v_opacity,
            &v_sh,
        ]
        .map(|b| &b.buffer);
        self.step_base(rec, &batch.params, v, it, plan, &status);
        watch.times.optimizer += watch.lap_recorded(rec)?;
        Ok(())
    }
}
