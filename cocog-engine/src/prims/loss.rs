//! GPU training loss (1 − λ)·L1 + λ·(1 − SSIM) and its gradient; see loss.wgsl.

use crate::EngineError;
use crate::core::{GpuBuffer, GpuContext, Kernel, Recorder, Workspace, shader};
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

/// The loss gradient (ready to pass to `Renderer::backward` as `v_rgba`) and the per-workgroup
/// partial sums the loss and PSNR are read from.
#[derive(Clone, Debug)]
pub struct LossOutput {
    /// ∂loss/∂pred per pixel, alpha component zero.
    pub v_pred: GpuBuffer,
    /// Per workgroup of 256 pixels: (Σ|pred − target|, Σ SSIM, Σ (clamp(pred) − target)², 0)
    /// over pixels and channels.
    pub partials: GpuBuffer,
    pub num_groups: usize,
    lambda: f64,
    inv_n: f64,
}

/// Loss and PSNR from the partial sums of a `LossOutput`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LossValue {
    pub loss: f64,
    /// dB, of the prediction clamped to [0, 1].
    pub psnr: f64,
}

impl LossOutput {
    /// Bytes of `partials` to read back (asynchronously or not) for `value_from`.
    pub fn partials_bytes(&self) -> u64 {
        self.num_groups as u64 * 16
    }

    /// The loss and PSNR from `partials_bytes` bytes of `partials`.
    pub fn value_from(&self, bytes: &[u8]) -> LossValue {
        let sums: &[[f32; 4]] = bytemuck::cast_slice(&bytes[..self.partials_bytes() as usize]);
        let (l1, ssim, sq) = sums.iter().fold((0.0, 0.0, 0.0), |(a, b, c), s| {
            (
                a + f64::from(s[0]),
                b + f64::from(s[1]),
                c + f64::from(s[2]),
            )
        });
        let mse = sq * self.inv_n;
        LossValue {
            loss: (1.0 - self.lambda) * l1 * self.inv_n + self.lambda * (1.0 - ssim * self.inv_n),
            psnr: 10.0 * (1.0 / mse.max(1e-20)).log10(),
        }
    }

    /// The loss value; one blocking GPU→CPU read, so call it only when the value is needed.
    pub fn read_loss(&self, ctx: &GpuContext) -> Result<f64, EngineError> {
        let sums: Vec<u8> = ctx.read(&self.partials, self.partials_bytes() as usize)?;
        Ok(self.value_from(&sums).loss)
    }
}

impl ImageLoss {
    /// Bytes of the largest buffer one binding of `compute` covers, for `pixels` pixels over
    /// all images: the SSIM moments, five rgba planes per pixel.
    pub fn largest_binding(pixels: u64) -> u64 {
        5 * 16 * pixels
    }

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
    /// laid out like `ForwardState::rgba`, averaged over images, pixels and channels. The
    /// gradient and partial sums live in `ws` until the next call.
    pub fn compute(
        &self,
        rec: &mut Recorder,
        ws: &mut Workspace,
        pred: &wgpu::Buffer,
        target: &wgpu::Buffer,
        width: u32,
        height: u32,
        num_images: u32,
        lambda: f32,
    ) -> LossOutput {
        let ctx = rec.ctx();
        let pixels = width * height * num_images;
        let groups = pixels.div_ceil(256);
        let taps = window();
        let inv_n = 1.0 / (3.0 * f64::from(pixels));
        let params = |count: u32| Params {
            width,
            height,
            num_images,
            count,
            lambda,
            inv_n: inv_n as f32,
            pad: [0; 2],
            weights: std::array::from_fn(|i| taps.get(i).map_or(0.0, |&w| w as f32)),
        };
        let (p5, p3) = (rec.uniform(&params(5)), rec.uniform(&params(3)));
        let px = u64::from(pixels) * 16;
        // The SSIM terms reuse the moments' scratch once the moments are consumed.
        let moments_bytes = Self::largest_binding(u64::from(pixels));
        let tmp = ws.buffer(ctx, "ssim tmp", moments_bytes);
        let moments = ws.buffer(ctx, "ssim moments", moments_bytes);
        let partials = ws.buffer(ctx, "loss partials", u64::from(groups) * 16);
        let v_pred = ws.buffer(ctx, "v_pred", px);
        let terms = ws.buffer(ctx, "ssim terms", 3 * px);
        self.moments_h
            .dispatch_1d(rec, &[(0, &p5), (1, pred), (2, target), (4, &tmp)], groups);
        self.blur_v
            .dispatch_1d(rec, &[(0, &p5), (3, &tmp), (4, &moments)], groups);
        self.terms.dispatch_1d(
            rec,
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
            .dispatch_1d(rec, &[(0, &p3), (3, &terms), (4, &tmp)], groups);
        self.blur_v
            .dispatch_1d(rec, &[(0, &p3), (3, &tmp), (4, &terms)], groups);
        self.grad.dispatch_1d(
            rec,
            &[(0, &p3), (1, pred), (2, target), (3, &terms), (4, &v_pred)],
            groups,
        );
        LossOutput {
            v_pred,
            partials,
            num_groups: groups as usize,
            lambda: f64::from(lambda),
            inv_n,
        }
    }
}
