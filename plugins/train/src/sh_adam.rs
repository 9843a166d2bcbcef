//! Adam for the SH buffer with separate DC and higher-order learning rates; see sh_adam.wgsl.

use cocog_engine::{AdamConfig, AdamMoments, GpuContext};

use crate::kernel::Kernel;

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    n: u32,
    coeffs: u32,
    lr_dc: f32,
    lr_rest: f32,
    beta1: f32,
    beta2: f32,
    eps: f32,
    bias1: f32,
    bias2: f32,
    pad: [u32; 3],
}

#[derive(Debug)]
pub(crate) struct ShAdam {
    kernel: Kernel,
}

impl ShAdam {
    pub(crate) fn new(ctx: &GpuContext) -> Self {
        Self {
            kernel: Kernel::new(ctx, include_str!("sh_adam.wgsl"), "sh_adam"),
        }
    }

    /// Records step `t` (1-based): DC coefficients move at `config.lr`, the rest at `lr_rest`.
    pub(crate) fn encode(
        &self,
        ctx: &GpuContext,
        encoder: &mut wgpu::CommandEncoder,
        param: &wgpu::Buffer,
        grad: &wgpu::Buffer,
        moments: &AdamMoments,
        coeffs_per_channel: u32,
        config: &AdamConfig,
        lr_rest: f32,
        t: u32,
    ) {
        if moments.len == 0 {
            return;
        }
        let t = i32::try_from(t.max(1)).unwrap_or(i32::MAX);
        let params = Params {
            n: moments.len,
            coeffs: coeffs_per_channel.max(1),
            lr_dc: config.lr,
            lr_rest,
            beta1: config.beta1,
            beta2: config.beta2,
            eps: config.eps,
            bias1: 1.0 - config.beta1.powi(t),
            bias2: 1.0 - config.beta2.powi(t),
            pad: [0; 3],
        };
        let buffers = [param, grad, &moments.m.buffer, &moments.v.buffer];
        self.kernel
            .dispatch_1d(ctx, encoder, &params, &buffers, moments.len);
    }
}
