//! cocog-engine: differentiable Gaussian splatting on wgpu compute shaders.
//!
//! The forward pass projects Gaussians (EWA splatting, SH colour), bins them into 16×16
//! tiles with a GPU prefix sum and radix sort, and composites each tile front to back. The
//! backward pass replays each tile back to front and chains the gradients to every
//! parameter. `reference` is an f64 CPU implementation of the same maths used for testing.

mod error;
pub mod gpu;
pub mod reference;
mod types;

pub use error::EngineError;
pub use gpu::{
    Adam, AdamConfig, AdamMoments, Batch, ForwardState, GpuBuffer, GpuContext, Gradients,
    ImageLoss, ImageSpec, LossOutput, MemoryTracker, ParamBuffers, PrefixSum, RadixSort,
    RenderedImage, Renderer, SortBuffers,
};
pub use types::{
    ALPHA_MAX, ALPHA_MIN, Camera, GaussianGrads, GaussianParams, LOW_PASS, MAX_SH_DEGREE,
    NEAR_PLANE, T_MIN, TILE_SIZE, View, sh_coeffs_per_channel,
};
