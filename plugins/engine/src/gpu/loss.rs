//! GPU training loss (1 − λ)·L1 + λ·(1 − SSIM) and its gradient; see loss.wgsl.

use super::GpuContext;
use super::buffers::GpuBuffer;
use super::kernel::{Kernel, shader};
use crate::EngineError;
use crate::reference::loss::window;

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    width: u32,
    height: u32,
    num_images: u32,
    count: u32,
    lambda: f32,
    inv_n: f32,
    pad: [u32; 2],
    weights: [f32; 12],
}

#[derive(Debug)]
pub struct ImageLoss {
    moments_h: Kernel,
    blur_h: Kernel,
    blur_v: Kernel,
    terms: Kernel,
    grad: Kernel,
}

/// The loss gradient (ready to pass to `Renderer::backward` as `v_rgba`) and the partial
/// sums the loss value is read from.
#[derive(Debug)]
pub struct LossOutput {
    /// ∂loss/∂pred per pixel, alpha component zero.
    pub v_pred: GpuBuffer,
    partials: GpuBuffer,
    num_groups: usize,
    lambda: f64,
    inv_n: f64,
}

impl LossOutput {
    /// The loss value; one GPU→CPU sync, so call it only when the value is needed.
    pub fn read_loss(&self, ctx: &GpuContext) -> Result<f64, EngineError> {
        let sums: Vec<[f32; 2]> = ctx.read(&self.partials, self.num_groups)?;
        let (l1, ssim) = sums.iter().fold((0.0, 0.0), |(a, b), s| {
            (a + f64::from(s[0]), b + f64::from(s[1]))
        });
        Ok((1.0 - self.lambda) * l1 * self.inv_n + self.lambda * (1.0 - ssim * self.inv_n))
    }
}

impl ImageLoss {
    pub fn new(ctx: &GpuContext) -> Self {
        let module = shader(ctx, "loss", include_str!("loss.wgsl"));
        Self {
            moments_h: Kernel::new(ctx, &module, "moments_h"),
            blur_h: Kernel::new(ctx, &module, "blur_h"),
            blur_v: Kernel::new(ctx, &module, "blur_v"),
            terms: Kernel::new(ctx, &module, "ssim_terms"),
            grad: Kernel::new(ctx, &module, "ssim_grad"),
        }
    }

    /// Loss of `pred` against `target`, both `num_images` rgba images of `width`×`height`
    /// laid out like `ForwardState::rgba`, averaged over images, pixels and channels.
    pub fn compute(
        &self,
        ctx: &GpuContext,
        pred: &wgpu::Buffer,
        target: &wgpu::Buffer,
        width: u32,
        height: u32,
        num_images: u32,
        lambda: f32,
    ) -> LossOutput {
        let pixels = width * height * num_images;
        let groups = pixels.div_ceil(256);
        let taps = window();
        let inv_n = 1.0 / (3.0 * f64::from(pixels));
        let params = |count: u32| {
            ctx.uniform(&Params {
                width,
                height,
                num_images,
                count,
                lambda,
                inv_n: inv_n as f32,
                pad: [0; 2],
                weights: std::array::from_fn(|i| taps.get(i).map_or(0.0, |&w| w as f32)),
            })
        };
        let (p5, p3) = (params(5), params(3));
        let px = u64::from(pixels) * 16;
        let (moments_tmp, moments) = (
            ctx.storage("ssim tmp", 5 * px),
            ctx.storage("ssim moments", 5 * px),
        );
        let (terms_tmp, terms) = (
            ctx.storage("ssim terms tmp", 3 * px),
            ctx.storage("ssim terms", 3 * px),
        );
        let partials = ctx.storage("loss partials", u64::from(groups) * 8);
        let v_pred = ctx.storage("v_pred", px);
        let mut enc = ctx.device.create_command_encoder(&Default::default());
        let e = &mut enc;
        self.moments_h.dispatch_1d(
            ctx,
            e,
            &[(0, &p5), (1, pred), (2, target), (4, &moments_tmp)],
            groups,
        );
        self.blur_v.dispatch_1d(
            ctx,
            e,
            &[(0, &p5), (3, &moments_tmp), (4, &moments)],
            groups,
        );
        self.terms.dispatch_1d(
            ctx,
            e,
            &[
                (0, &p5),
                (1, pred),
                (2, target),
                (3, &moments),
                (4, &terms),
                (5, &partials),
            ],
            groups,
        );
        self.blur_h
            .dispatch_1d(ctx, e, &[(0, &p3), (3, &terms), (4, &terms_tmp)], groups);
        self.blur_v
            .dispatch_1d(ctx, e, &[(0, &p3), (3, &terms_tmp), (4, &terms)], groups);
        self.grad.dispatch_1d(
            ctx,
            e,
            &[(0, &p3), (1, pred), (2, target), (3, &terms), (4, &v_pred)],
            groups,
        );
        ctx.queue.submit([enc.finish()]);
        LossOutput {
            v_pred,
            partials,
            num_groups: groups as usize,
            lambda: f64::from(lambda),
            inv_n,
        }
    }
}
