//! cocog-engine: differentiable Gaussian splatting on wgpu compute shaders.
//!
//! The forward pass projects Gaussians (EWA splatting, SH colour), sorts them by depth, emits
//! one key per covered 16×16 tile, radix-sorts the keys by tile and composites each tile
//! front to back. The backward pass replays each tile back to front and chains the gradients
//! to every parameter. Several images, each with its own Gaussians and camera, render in one
//! launch (the image index is a grid dimension). `reference` is an f64 CPU implementation of
//! the same maths, used to validate the kernels and finite-differenced in the tests.
//!
//! A training step, all on the GPU (only `forward` syncs, to size its tile buffers):
//! ```no_run
//! # use cocog_engine::*;
//! # fn step(ctx: &GpuContext, views: &[View<'_>], target: &wgpu::Buffer) -> Result<(), EngineError> {
//! let (renderer, loss, adam) = (Renderer::new(ctx), ImageLoss::new(ctx), Adam::new(ctx));
//! let batch = Batch::from_views(ctx, views)?;
//! let state = renderer.forward(ctx, &batch)?;
//! let (w, h, n) = (batch.width(), batch.height(), batch.num_images());
//! let out = loss.compute(ctx, &state.rgba, target, w, h, n, 0.2);
//! let v_depth = ctx.storage("v_depth", u64::from(w * h * n) * 4);
//! let grads = renderer.backward(ctx, &batch, &state, &out.v_pred, &v_depth);
//! let moments = AdamMoments::new(ctx, 3 * batch.params.num_gaussians);
//! let mut enc = ctx.device.create_command_encoder(&Default::default());
//! let lr = AdamConfig::with_lr(1.6e-4);
//! adam.encode(ctx, &mut enc, &batch.params.means, &grads.params.means, &moments, &lr, 1);
//! ctx.queue.submit([enc.finish()]);
//! # Ok(()) }
//! ```
//!
//! Conventions: OpenCV cameras (x right, y down, z forward) with `world_from_camera` poses;
//! pixel (i, j) is centred at (i + 0.5, j + 0.5); parameters are laid out as in an INRIA PLY
//! (see `GaussianParams`); `depth` output is Σ wᵢ·zᵢ, not divided by alpha.

mod error;
pub mod gpu;
pub mod reference;
mod splats;
mod types;

pub use error::EngineError;
pub use gpu::{
    Adam, AdamConfig, AdamMoments, Batch, ForwardState, GpuBuffer, GpuContext, Gradients,
    ImageLoss, ImageSpec, Kernel, LossOutput, MemoryTracker, ParamBuffers, PrefixSum, RadixSort,
    RenderedImage, Renderer, SortBuffers, shader, test_gpu,
};
pub use types::{
    ALPHA_MAX, ALPHA_MIN, Camera, GaussianGrads, GaussianParams, LOW_PASS, MAX_SH_DEGREE,
    NEAR_PLANE, T_MIN, TILE_SIZE, View, sh_coeffs_per_channel,
};
