//! GPU training loss (1 − λ)·L1 + λ·(1 − SSIM) and its gradient; see loss.wgsl.

use crate::EngineError;
use crate::core::{Bind, GpuBuffer, GpuContext, Kernel, Recorder, Workspace, shader};
use crate::error::mib;
use crate::reference::loss::window;

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    width: u32,
    height: u32,
    num_images: u32,
    pad: u32,
    lambda: f32,
    inv_n: f32,
    row0: i32,
    rows: u32,
    out0: i32,
    out1: i32,
    pixel0: u32,
    partial0: u32,
    weights: [f32; 12],
}

/// Rows each side of the scored ones whose SSIM terms their gradient's blur reads.
const HALO: u32 = 5;
/// A tile of loss.wgsl's passes: columns × rows.
const TILE: (u32, u32) = (16, 8);

#[derive(Debug)]
pub struct ImageLoss {
    forward: Kernel,
    backward: Kernel,
    /// Largest buffer binding to plan for; the device's limit unless a test lowers it.
    binding_limit: Option<u64>,
}

/// One pass of the loss over scratch rows `row0..row0 + rows` of `num_images` images
/// starting at pixel `pixel0`, scoring rows `out.0..out.1` (within the scratch's rows, which
/// hold `HALO` more each side where the image has them).
struct Band {
    row0: i32,
    rows: u32,
    out: (i32, i32),
    num_images: u32,
    pixel0: u32,
}

/// Which rows of an image `ImageLoss::compute_rows` scores, and the pixel count of the whole
/// loss they are part of.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LossRows {
    pub out: (u32, u32),
    pub frame_pixels: u64,
}

impl Band {
    /// The forward's tiles: columns, scratch rows, images. It writes one partial sum each.
    fn forward_grid(&self, width: u32) -> [u32; 3] {
        [
            width.div_ceil(TILE.0),
            self.rows.div_ceil(TILE.1),
            self.num_images,
        ]
    }

    /// The backward's tiles, over the scored rows.
    fn backward_grid(&self, width: u32) -> [u32; 3] {
        let scored = (self.out.1 - self.out.0).max(0) as u32;
        [
            width.div_ceil(TILE.0),
            scored.div_ceil(TILE.1),
            self.num_images,
        ]
    }
}

/// The loss gradient (ready to pass to `Renderer::backward` as `v_rgba`) and the per-workgroup
/// partial sums the loss and PSNR are read from.
#[derive(Clone, Debug)]
pub struct LossOutput {
    /// ∂loss/∂pred per pixel, alpha component zero.
    pub v_pred: GpuBuffer,
    /// Per 16×8 tile: (Σ|pred − target|, Σ SSIM, Σ (clamp(pred) − target)², 0)
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
    /// The same loss read from other partial sums: those of every band of a frame, gathered
    /// into one buffer (`ImageLoss::compute_rows` scales each band's as a part of the frame's).
    pub fn with_partials(&self, partials: GpuBuffer, num_groups: usize) -> LossOutput {
        LossOutput {
            partials,
            num_groups,
            ..self.clone()
        }
    }

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
    /// Bytes of the largest scratch buffer one binding of `compute` covers when the whole
    /// batch is one pass, for `pixels` pixels over all images: the SSIM terms, three rgba
    /// planes per pixel. Past the binding limit `compute` works in bands of rows instead.
    pub fn largest_binding(pixels: u64) -> u64 {
        3 * 16 * pixels
    }

    /// Plans for at most `bytes` per buffer binding instead of the device's limit (tests of
    /// the banded path at small sizes).
    pub fn with_binding_limit(mut self, bytes: u64) -> Self {
        self.binding_limit = Some(bytes);
        self
    }

    /// The partial sums `compute_rows` writes for these arguments (its output's
    /// `num_groups`), so a caller can gather several calls' sums in one buffer.
    pub fn slots(
        &self,
        ctx: &GpuContext,
        width: u32,
        height: u32,
        num_images: u32,
        rows: LossRows,
    ) -> Result<u32, EngineError> {
        let bands = self.plan(ctx, width, height, num_images, rows.out)?;
        Ok(Self::slots_of(&bands, width))
    }

    fn slots_of(bands: &[Band], width: u32) -> u32 {
        bands
            .iter()
            .map(|b| b.forward_grid(width).iter().product::<u32>())
            .sum()
    }

    fn plan(
        &self,
        ctx: &GpuContext,
        width: u32,
        height: u32,
        num_images: u32,
        out: (u32, u32),
    ) -> Result<Vec<Band>, EngineError> {
        let limit = self.binding_limit.unwrap_or_else(|| ctx.binding_limit());
        Self::bands(limit, width, height, num_images, out)
    }

    /// The passes for `num_images` images of `width`×`height`: one over everything when its
    /// scratch fits a binding, else bands of rows per image, each with its halo. A band
    /// scores at least one row and needs its halo, so a frame wider than `limit` allows for
    /// `2·HALO + 1` rows of terms is refused rather than planned past the limit.
    fn bands(
        limit: u64,
        width: u32,
        height: u32,
        num_images: u32,
        out: (u32, u32),
    ) -> Result<Vec<Band>, EngineError> {
        // The scratch rows of scored rows y0..y1: HALO more each side, within the image.
        let scratch = move |y0: u32, y1: u32| {
            let row0 = y0.saturating_sub(HALO);
            (row0 as i32, (y1 + HALO).min(height) - row0)
        };
        let (row0, rows) = scratch(out.0, out.1);
        let pixels = u64::from(width) * u64::from(rows) * u64::from(num_images);
        if Self::largest_binding(pixels) <= limit {
            return Ok(vec![Band {
                row0,
                rows,
                out: (out.0 as i32, out.1 as i32),
                num_images,
                pixel0: 0,
            }]);
        }
        let rows_fit = limit / Self::largest_binding(u64::from(width));
        let min_rows = u64::from(2 * HALO + 1);
        if rows_fit < min_rows.min(u64::from(height)) {
            return Err(EngineError::FrameTooWide {
                width,
                rows: min_rows as u32,
                needed_mib: mib(min_rows * Self::largest_binding(u64::from(width))),
                limit_mib: mib(limit),
            });
        }
        // Within the limit: a band's scratch is its rows plus a halo each side, clipped to the
        // image, and at least one row fits with its halo (or the whole image's height does).
        let band = (rows_fit.saturating_sub(u64::from(2 * HALO)) as u32).clamp(1, height);
        Ok((0..num_images)
            .flat_map(|image| {
                (out.0..out.1).step_by(band as usize).map(move |y0| {
                    let y1 = (y0 + band).min(out.1);
                    let (row0, rows) = scratch(y0, y1);
                    Band {
                        row0,
                        rows,
                        out: (y0 as i32, y1 as i32),
                        num_images: 1,
                        pixel0: image * width * height,
                    }
                })
            })
            .collect())
    }

    pub fn new(ctx: &GpuContext) -> Self {
        let module = shader(ctx, "loss", include_str!("loss.wgsl"));
        Self {
            forward: Kernel::new(ctx, &module, "ssim_forward"),
            backward: Kernel::new(ctx, &module, "ssim_backward"),
            binding_limit: None,
        }
    }

    /// Loss of `pred` against `target`, both `num_images` rgba images of `width`×`height`
    /// laid out like `ForwardState::rgba`, averaged over images, pixels and channels. The
    /// gradient and partial sums live in `ws` until the next call.
    pub fn compute(
        &self,
        rec: &mut Recorder,
        ws: &mut Workspace,
        pred: &dyn Bind,
        target: &dyn Bind,
        width: u32,
        height: u32,
        num_images: u32,
        lambda: f32,
    ) -> Result<LossOutput, EngineError> {
        let rows = LossRows {
            out: (0, height),
            frame_pixels: u64::from(width) * u64::from(height) * u64::from(num_images),
        };
        self.compute_rows(
            rec, ws, pred, target, width, height, num_images, rows, lambda,
        )
    }

    /// One band of a frame too large for a buffer binding: `pred` and `target` hold rows
    /// of one image (the band and its halo), of which `rows.out` are scored, with the sums
    /// scaled as parts of a loss over `rows.frame_pixels` pixels. The gradient is zero
    /// outside `rows.out`; that of a scored row is exact when the band holds 10 rows beyond
    /// it on each side (or the frame ends there), so the bands of a frame add up to its loss
    /// and gradient.
    pub fn compute_rows(
        &self,
        rec: &mut Recorder,
        ws: &mut Workspace,
        pred: &dyn Bind,
        target: &dyn Bind,
        width: u32,
        height: u32,
        num_images: u32,
        rows: LossRows,
        lambda: f32,
    ) -> Result<LossOutput, EngineError> {
        let ctx = rec.ctx();
        let pixels = width * height * num_images;
        let taps = window();
        let inv_n = 1.0 / (3.0 * rows.frame_pixels as f64);
        let bands = self.plan(ctx, width, height, num_images, rows.out)?;
        let scratch_px = |b: &Band| width * b.rows * b.num_images;
        let largest = bands.iter().map(scratch_px).max().unwrap_or(0);
        let slots = Self::slots_of(&bands, width);
        let terms = ws.buffer(ctx, "ssim terms", 3 * 16 * u64::from(largest));
        let partials = ws.buffer(ctx, "loss partials", u64::from(slots) * 16);
        let v_pred = if rows.out == (0, height) {
            ws.buffer(ctx, "v_pred", u64::from(pixels) * 16)
        } else {
            ws.zeroed(rec, "v_pred", u64::from(pixels) * 16)
        };
        let mut partial0 = 0;
        for band in &bands {
            let u = rec.uniform(&Params {
                width,
                height,
                num_images: band.num_images,
                pad: 0,
                lambda,
                inv_n: inv_n as f32,
                row0: band.row0,
                rows: band.rows,
                out0: band.out.0,
                out1: band.out.1,
                pixel0: band.pixel0,
                partial0,
                weights: std::array::from_fn(|i| taps.get(i).map_or(0.0, |&w| w as f32)),
            });
            let shared: [(u32, &dyn Bind); 4] = [(0, &u), (1, pred), (2, target), (3, &terms)];
            let forward = [shared.as_slice(), &[(5, &partials)]].concat();
            let backward = [shared.as_slice(), &[(4, &v_pred)]].concat();
            self.forward
                .dispatch(rec, &forward, band.forward_grid(width));
            self.backward
                .dispatch(rec, &backward, band.backward_grid(width));
            partial0 += band.forward_grid(width).iter().product::<u32>();
        }
        Ok(LossOutput {
            v_pred,
            partials,
            num_groups: slots as usize,
            lambda: f64::from(lambda),
            inv_n,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every planned pass stays within the binding limit, and the bands score each requested
    /// row of each image exactly once with its full halo where the image has one.
    #[test]
    fn bands_fit_the_limit_and_cover_every_row_once() {
        for (width, height, images) in [(7, 3, 1), (16, 40, 2), (33, 11, 3), (5, 100, 1)] {
            let row = ImageLoss::largest_binding(u64::from(width));
            for rows_fit in [1, 3, 10, 11, 12, 25, 1000] {
                let limit = rows_fit * row + row / 2;
                let out = (0, height);
                let Ok(bands) = ImageLoss::bands(limit, width, height, images, out) else {
                    assert!(rows_fit < 11 && rows_fit < u64::from(height));
                    continue;
                };
                let mut scored = vec![0u32; (height * images) as usize];
                for b in &bands {
                    let px = u64::from(width) * u64::from(b.rows) * u64::from(b.num_images);
                    assert!(ImageLoss::largest_binding(px) <= limit, "{width}x{height}");
                    assert!(b.row0 <= (b.out.0 - HALO as i32).max(0));
                    let end = b.row0 + b.rows as i32;
                    assert!(end >= (b.out.1 + HALO as i32).min(height as i32));
                    for image in 0..b.num_images {
                        let first = b.pixel0 / (width * height) + image;
                        for y in b.out.0..b.out.1 {
                            scored[(first * height) as usize + y as usize] += 1;
                        }
                    }
                }
                assert!(
                    scored.iter().all(|&n| n == 1),
                    "{width}x{height} {rows_fit}"
                );
            }
        }
    }

    /// A frame too wide for one scored row and its halo in a binding is an error naming the
    /// width, never a plan past the limit.
    #[test]
    fn a_frame_too_wide_for_its_halo_is_refused() {
        let width = 1000;
        let limit = 10 * ImageLoss::largest_binding(width.into());
        match ImageLoss::bands(limit, width, 50, 1, (0, 50)) {
            Err(EngineError::FrameTooWide { width: w, .. }) => assert_eq!(w, width),
            Err(e) => panic!("unexpected error: {e}"),
            Ok(_) => panic!("planned bands past the binding limit"),
        }
        // Eleven rows fit: one scored row per band.
        let bands = ImageLoss::bands(
            limit + ImageLoss::largest_binding(width.into()),
            width,
            50,
            1,
            (0, 50),
        )
        .expect("eleven rows fit");
        assert_eq!(bands.len(), 50);
    }
}
