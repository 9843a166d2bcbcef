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

#[cfg(test)]
mod tests {
    use super::*;

    /// Adam's first step moves every element by exactly lr·sign(g) (m̂ = g, √v̂ = |g|), so the
    /// per-coefficient rate shows directly in the parameter change.
    #[test]
    fn dc_and_higher_order_coefficients_get_their_own_rates() {
        let ctx = match GpuContext::new() {
            Ok(ctx) => ctx,
            Err(e) => {
                assert!(
                    std::env::var("CI").as_deref() != Ok("true"),
                    "CI=true but no usable GPU adapter: {e}"
                );
                eprintln!("skipping GPU test: {e}");
                return;
            }
        };
        // Two Gaussians at degree 1: 3 channels × 4 coefficients each.
        let n = 24;
        let grad: Vec<f32> = (0..n)
            .map(|i| if i % 3 == 0 { -0.5 } else { 0.25 })
            .collect();
        let param = ctx.storage_from("param", &vec![1.0f32; n]);
        let grad_buf = ctx.storage_from("grad", &grad);
        let moments = AdamMoments::new(&ctx, n as u32);
        let mut enc = ctx.device.create_command_encoder(&Default::default());
        let config = AdamConfig::with_lr(0.01);
        ShAdam::new(&ctx).encode(
            &ctx, &mut enc, &param, &grad_buf, &moments, 4, &config, 0.0005, 1,
        );
        ctx.queue.submit([enc.finish()]);
        let out: Vec<f32> = ctx.read(&param, n).unwrap();
        for (i, (p, g)) in out.iter().zip(&grad).enumerate() {
            let lr = if i % 4 == 0 { 0.01 } else { 0.0005 };
            let want = 1.0 - lr * g.signum();
            assert!((p - want).abs() < 1e-6, "element {i}: {p} vs {want}");
        }
    }
}
