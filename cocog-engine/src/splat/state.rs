//! What a forward pass leaves on the GPU, what a backward returns, and their readback.

use super::batch::{Batch, ParamBuffers};
use crate::EngineError;
use crate::core::GpuBuffer;
use crate::core::GpuContext;

/// Outputs of a forward pass plus what its backward replays. Pixels are `[image][y][x]`.
#[derive(Debug)]
pub struct ForwardState {
    /// Colour (background composited) in rgb and alpha = 1 − final transmittance in w.
    pub rgba: GpuBuffer,
    /// Σ wᵢ·zᵢ over composited Gaussians (camera z); divide by alpha for the mean depth.
    pub depth: GpuBuffer,
    pub(crate) final_t: GpuBuffer,
    pub(crate) last: GpuBuffer,
    /// Per Gaussian, three vec4: (mean2d, camera z, opacity), (conic xx, xy, yy, radius in
    /// pixels), (rgb, 0). All zero for culled Gaussians, so radius > 0 marks visibility
    /// (what densification's max-radius statistic needs).
    pub projected: GpuBuffer,
    pub(crate) ranges: GpuBuffer,
    pub(crate) tile_values: GpuBuffer,
    /// [overflowed (0 or 1), intersections needed], written on the GPU.
    pub status: GpuBuffer,
    /// (tile, Gaussian) pairs this pass composited from; exact after `Renderer::forward`,
    /// the capacity after `encode_forward` (the count is in `status`).
    pub num_intersections: u32,
    /// Chunks per tile list the backward walks (`RasterSplit`), and where each starts: per
    /// pixel, [slot][pixel] (colour in front, transmittance) and depth in front.
    pub(crate) splits: u32,
    pub(crate) chunk_state: GpuBuffer,
    pub(crate) chunk_depth: GpuBuffer,
    /// The shortest chunk the forward cut a list into (`RasterSplit`).
    pub(crate) min_chunk: u32,
}

/// Output of `Renderer::backward`.
#[derive(Debug)]
pub struct Gradients {
    /// Gradients of every parameter, laid out like the batch's parameters.
    pub params: ParamBuffers,
    /// Screen-space gradients per Gaussian, 10 floats each: mean2d (2), conic (3), colour (3),
    /// opacity, depth. ‖mean2d‖ is the statistic 3DGS-style densification accumulates.
    pub v_projected: GpuBuffer,
}

/// One image read back to the CPU, row-major.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderedImage {
    pub width: u32,
    pub height: u32,
    pub color: Vec<[f32; 3]>,
    pub alpha: Vec<f32>,
    pub depth: Vec<f32>,
}

impl ForwardState {
    /// Chunks per tile list the backward of this pass walks (`RasterSplit`; 1: whole lists).
    pub fn splits(&self) -> u32 {
        self.splits
    }

    /// Reads every image of the batch back to the CPU.
    pub fn read_images(
        &self,
        ctx: &GpuContext,
        batch: &Batch,
    ) -> Result<Vec<RenderedImage>, EngineError> {
        let (w, h) = (batch.width(), batch.height());
        let per = (w * h) as usize;
        let total = per * batch.images.len();
        let rgba: Vec<[f32; 4]> = ctx.read(&self.rgba, total)?;
        let depth: Vec<f32> = ctx.read(&self.depth, total)?;
        Ok((0..batch.images.len())
            .map(|i| {
                let px = &rgba[i * per..(i + 1) * per];
                RenderedImage {
                    width: w,
                    height: h,
                    color: px.iter().map(|p| [p[0], p[1], p[2]]).collect(),
                    alpha: px.iter().map(|p| p[3]).collect(),
                    depth: depth[i * per..(i + 1) * per].to_vec(),
                }
            })
            .collect())
    }
}
