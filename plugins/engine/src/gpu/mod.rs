//! The wgpu side of the engine.

mod adam;
mod batch;
mod buffers;
mod context;
mod kernel;
mod loss;
mod renderer;
mod scan;
mod sort;

pub use adam::{Adam, AdamConfig, AdamMoments};
pub use batch::{Batch, ImageSpec, ParamBuffers};
pub use buffers::{GpuBuffer, MemoryTracker};
pub use context::GpuContext;
pub use loss::{ImageLoss, LossOutput};
pub use renderer::{ForwardState, Gradients, RenderedImage, Renderer};
pub use scan::PrefixSum;
pub use sort::{RadixSort, SortBuffers};
