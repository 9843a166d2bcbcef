//! Adam optimiser step on GPU parameter buffers; see adam.wgsl.

use crate::core::{GpuBuffer, GpuContext, Kernel, Recorder, shader};

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    n: u32,
    lr: f32,
    beta1: f32,
    beta2: f32,
    eps: f32,
    bias1: f32,
    bias2: f32,
    period: u32,
    lr_rest: f32,
    pad: [u32; 3],
}

/// Hyper-parameters of one parameter group.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AdamConfig {
    pub lr: f32,
    pub beta1: f32,
    pub beta2: f32,
    pub eps: f32,
    /// Two groups in one buffer: `Some((period, lr_rest))` steps only every `period`-th
    /// element (from 0) at `lr` and the others at `lr_rest` (SH: DC and higher bands).
    pub interleaved: Option<(u32, f32)>,
}

impl AdamConfig {
    /// β = (0.9, 0.999) and ε = 1e-15, as 3DGS and CoCoGaussian configure torch's Adam.
    pub fn with_lr(lr: f32) -> Self {
        Self {
            lr,
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-15,
            interleaved: None,
        }
    }

    /// The same with every element not at a multiple of `period` stepping at `lr_rest`.
    pub fn interleaved(self, period: u32, lr_rest: f32) -> Self {
        Self {
            interleaved: Some((period.max(1), lr_rest)),
            ..self
        }
    }
}

/// First and second moments of one parameter buffer of `len` floats.
#[derive(Debug)]
pub struct AdamMoments {
    pub m: GpuBuffer,
    pub v: GpuBuffer,
    pub len: u32,
}

impl AdamMoments {
    pub fn new(ctx: &GpuContext, len: u32) -> Self {
        Self {
            m: ctx.storage("adam m", u64::from(len) * 4),
            v: ctx.storage("adam v", u64::from(len) * 4),
            len,
        }
    }
}

#[derive(Debug)]
pub struct Adam {
    kernel: Kernel,
    /// Bound as the skip flag when the caller has none.
    never_skip: GpuBuffer,
}

impl Adam {
    pub fn new(ctx: &GpuContext) -> Self {
        let module = shader(ctx, "adam", include_str!("adam.wgsl"));
        Self {
            kernel: Kernel::new(ctx, &module, "adam"),
            never_skip: ctx.storage("adam never skip", 16),
        }
    }

    /// Records step `t` (1-based) of Adam on the first `moments.len` floats of `param`;
    /// nothing changes on the GPU if element 0 of `skip` is non-zero when it runs.
    pub fn encode(
        &self,
        rec: &mut Recorder,
        param: &wgpu::Buffer,
        grad: &wgpu::Buffer,
        moments: &AdamMoments,
        config: &AdamConfig,
        t: u32,
        skip: Option<&wgpu::Buffer>,
    ) {
        if moments.len == 0 {
            return;
        }
        let t = i32::try_from(t.max(1)).unwrap_or(i32::MAX);
        let (period, lr_rest) = config.interleaved.unwrap_or((1, config.lr));
        let params = rec.uniform(&Params {
            n: moments.len,
            lr: config.lr,
            beta1: config.beta1,
            beta2: config.beta2,
            eps: config.eps,
            bias1: 1.0 - config.beta1.powi(t),
            bias2: 1.0 - config.beta2.powi(t),
            period: period.max(1),
            lr_rest,
            pad: [0; 3],
        });
        let skip = skip.unwrap_or(&self.never_skip.buffer);
        self.kernel.dispatch_1d(
            rec,
            &[
                (0, &params),
                (1, param),
                (2, grad),
                (3, &moments.m),
                (4, &moments.v),
                (5, skip),
            ],
            moments.len.div_ceil(256),
        );
    }
}
