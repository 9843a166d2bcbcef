//! Densification statistics accumulated on the GPU every iteration; see stats.wgsl.

use cocog_engine::{
    Bind, ForwardState, GpuBuffer, GpuContext, Gradients, Kernel, Recorder, shader,
};

use crate::TrainError;

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    n: u32,
    half_width: f32,
    half_height: f32,
    sets: u32,
}

/// Per Gaussian: Σ‖∂loss/∂mean2d‖ (NDC units) over the views it was visible in, and how many.
#[derive(Debug)]
pub struct GradStats {
    kernel: Kernel,
    accum: GpuBuffer,
    denom: GpuBuffer,
    len: u32,
}

fn accumulate_kernel(ctx: &GpuContext) -> Kernel {
    Kernel::new(
        ctx,
        &shader(ctx, "stats", include_str!("stats.wgsl")),
        "accumulate",
    )
}

impl GradStats {
    pub fn new(ctx: &GpuContext, num_gaussians: u32) -> Self {
        Self {
            kernel: accumulate_kernel(ctx),
            accum: ctx.storage("grad accum", u64::from(num_gaussians) * 4),
            denom: ctx.storage("grad denom", u64::from(num_gaussians) * 4),
            len: num_gaussians,
        }
    }

    /// Statistics restored from a checkpoint (`read_raw`'s output).
    pub fn from_raw(ctx: &GpuContext, accum: &[f32], denom: &[f32]) -> Self {
        Self {
            kernel: accumulate_kernel(ctx),
            accum: ctx.storage_from("grad accum", accum),
            denom: ctx.storage_from("grad denom", denom),
            len: accum.len() as u32,
        }
    }

    /// The running sums and counts of the first `rows` Gaussians, for a checkpoint.
    pub fn read_raw(
        &self,
        ctx: &GpuContext,
        rows: u32,
    ) -> Result<(Vec<f32>, Vec<f32>), TrainError> {
        let n = rows.min(self.len) as usize;
        Ok((ctx.read(&self.accum, n)?, ctx.read(&self.denom, n)?))
    }

    /// Zeroed statistics for `num_gaussians` (after densification changed the count).
    pub fn reset(&mut self, ctx: &GpuContext, num_gaussians: u32) {
        self.accum = ctx.storage("grad accum", u64::from(num_gaussians) * 4);
        self.denom = ctx.storage("grad denom", u64::from(num_gaussians) * 4);
        self.len = num_gaussians;
    }

    /// Room for `needed` Gaussians: when short, buffers of `grown` keeping the live
    /// statistics (the copy recorded in `rec`).
    pub fn reserve(&mut self, rec: &mut Recorder, needed: u32, grown: u32) {
        if self.accum.size() >= u64::from(needed) * 4 {
            return;
        }
        let bytes = u64::from(grown.max(needed)) * 4;
        let ctx = rec.ctx();
        let live = u64::from(self.len) * 4;
        for (old, name) in [
            (&mut self.accum, "grad accum"),
            (&mut self.denom, "grad denom"),
        ] {
            let grown = ctx.storage(name, bytes);
            if live > 0 {
                rec.encoder().copy_buffer_to_buffer(old, 0, &grown, 0, live);
            }
            *old = grown;
        }
    }

    /// Records zeroing the statistics of `n` Gaussians (after densification set that count);
    /// the buffers must hold them (`reserve`).
    pub fn restart(&mut self, rec: &mut Recorder, n: u32) {
        debug_assert!(self.accum.size() >= u64::from(n) * 4);
        rec.encoder().clear_buffer(&self.accum, 0, None);
        rec.encoder().clear_buffer(&self.denom, 0, None);
        self.len = n;
    }

    /// Keeps the statistics of the first `n` Gaussians only (the rest were buried rows).
    pub fn truncate(&mut self, n: u32) {
        self.len = self.len.min(n);
    }

    /// The running sums and visible-view counts.
    pub fn buffers(&self) -> (&GpuBuffer, &GpuBuffer) {
        (&self.accum, &self.denom)
    }

    /// Records adding one single-image pass of `width`×`height`; a pass whose intersection
    /// buffers overflowed (`state.status`) adds nothing.
    pub fn accumulate(
        &self,
        rec: &mut Recorder,
        state: &ForwardState,
        grads: &Gradients,
        width: u32,
        height: u32,
    ) {
        self.accumulate_sets(rec, state, grads, width, height, 1);
    }

    /// The same over a pass that rendered `sets` copies of every Gaussian (`[set][base]`, the
    /// CoC sets): each visible copy adds its norm and 1/`sets` of a view.
    pub fn accumulate_sets(
        &self,
        rec: &mut Recorder,
        state: &ForwardState,
        grads: &Gradients,
        width: u32,
        height: u32,
        sets: u32,
    ) {
        let pass: (&dyn Bind, &dyn Bind, &dyn Bind) =
            (&state.projected, &grads.v_projected, &state.status);
        self.accumulate_from(rec, pass, width, height, sets);
    }

    /// The same from a pass's (projected records, their gradients, status) buffers, laid out
    /// as the renderer's: e.g. a frame's gathered from its bands.
    pub fn accumulate_from(
        &self,
        rec: &mut Recorder,
        (projected, v_projected, status): (&dyn Bind, &dyn Bind, &dyn Bind),
        width: u32,
        height: u32,
        sets: u32,
    ) {
        let uniform = rec.uniform(&Params {
            n: self.len,
            half_width: 0.5 * width as f32,
            half_height: 0.5 * height as f32,
            sets: sets.max(1),
        });
        self.kernel.dispatch_1d(
            rec,
            &[
                (0, &uniform),
                (1, projected),
                (2, v_projected),
                (3, &self.accum),
                (4, &self.denom),
                (5, status),
            ],
            self.len.div_ceil(256),
        );
    }

    /// Mean gradient norm per Gaussian, 0 where never visible (INRIA turns its NaN into 0).
    pub fn read_mean(&self, ctx: &GpuContext) -> Result<Vec<f32>, TrainError> {
        let accum: Vec<f32> = ctx.read(&self.accum, self.len as usize)?;
        let denom: Vec<f32> = ctx.read(&self.denom, self.len as usize)?;
        Ok(accum
            .iter()
            .zip(&denom)
            .map(|(a, d)| if *d > 0.0 { a / d } else { 0.0 })
            .collect())
    }
}
