//! cocog-engine: differentiable Gaussian splatting on wgpu compute shaders.
//!
//! The forward pass projects Gaussians (EWA splatting, SH colour), sorts them by depth, emits
//! one key per covered 16×16 tile, radix-sorts the keys by tile and composites each tile
//! front to back. The backward pass replays each tile back to front and chains the gradients
//! to every parameter. Several images, each with its own Gaussians and camera, render in one
//! launch (the image index is a grid dimension). `reference` is an f64 CPU implementation of
//! the same maths, used to validate the kernels and finite-differenced in the tests.
//!
//! A training step, recorded into one submission that neither allocates (once the workspace
//! has grown to size) nor waits for the GPU:
//! ```no_run
//! # use cocog_engine::*;
//! # fn step(ctx: &GpuContext, views: &[View<'_>], target: &wgpu::Buffer) -> Result<(), EngineError> {
//! let (renderer, loss, adam) = (Renderer::new(ctx), ImageLoss::new(ctx), Adam::new(ctx));
//! let batch = Batch::from_views(ctx, views)?;
//! let (w, h, n) = (batch.width(), batch.height(), batch.num_images());
//! let mut ws = Workspace::default();
//! let moments = AdamMoments::new(ctx, 3 * batch.params.num_gaussians);
//! let mut rec = ctx.recorder();
//! let state = renderer.encode_forward(&mut rec, &mut ws, &batch, 1 << 20);
//! let out = loss.compute(&mut rec, &mut ws, &state.rgba, target, w, h, n, 0.2)?;
//! let grads = renderer.encode_backward(&mut rec, &mut ws, &batch, &state, &out.v_pred, None);
//! let lr = AdamConfig::with_lr(1.6e-4);
//! // An overflowed intersection buffer (state.status) makes the update a no-op on the GPU.
//! let (p, g) = (&batch.params.means, &grads.params.means);
//! adam.encode(&mut rec, p, g, &moments, &lr, 1, Some(&state.status));
//! rec.submit();
//! # Ok(()) }
//! ```
//!
//! Modules: `core` (device, buffers, dispatch), `prims` (Gaussian-agnostic kernels),
//! `splat` (the rasterizer), `coc` (CoCoGaussian's MLP h_θ and CoC expansion), `nn` (its
//! image-space compositor F), `reference` (the f64 CPU oracle).
//!
//! Conventions: OpenCV cameras (x right, y down, z forward) with `world_from_camera` poses;
//! pixel (i, j) is centred at (i + 0.5, j + 0.5); parameters are laid out as in an INRIA PLY
//! (see `GaussianParams`); `depth` output is Σ wᵢ·zᵢ, not divided by alpha.

pub mod coc;
pub mod core;
mod error;
pub mod nn;
pub mod prims;
pub mod reference;
pub mod splat;
mod splats;
mod types;

pub use crate::core::{
    Bind, CoopFragments, CounterSnapshot, Counters, GpuBuffer, GpuContext, Kernel, KernelProfiler,
    KernelTime, MemoryTracker, Readback, Recorder, UniformSlot, Workspace,
    device_select_probe_is_futile, quiet_headless_vulkan, runtime_checks, shader, test_gpu,
};
pub use error::EngineError;
pub use prims::{
    Adam, AdamConfig, AdamMoments, AddInto, CoopBlock, Gemm, GemmLayout, GemmShape, GemmTile,
    ImageLoss, LossOutput, LossRows, LossValue, OperandScales, PrefixSum, RadixSort, SortBuffers,
    SortCount,
};
pub use splat::{
    Batch, Crop, ForwardState, Frame, Gradients, ImageSpec, ParamBuffers, RasterBlocks,
    RasterSplit, RenderedImage, Renderer, bytes_per_gaussian, check_fits, check_fits_at,
};
pub use types::{
    ALPHA_MAX, ALPHA_MIN, Camera, GaussianGrads, GaussianParams, LOW_PASS, MAX_SH_DEGREE,
    NEAR_PLANE, T_MIN, TILE_SIZE, View, sh_coeffs_per_channel,
};
