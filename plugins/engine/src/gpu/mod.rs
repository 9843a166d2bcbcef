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
mod state;

pub use adam::{Adam, AdamConfig, AdamMoments};
pub use batch::{Batch, ImageSpec, ParamBuffers};
pub use buffers::{GpuBuffer, MemoryTracker};
pub use context::{GpuContext, test_gpu};
pub use kernel::{Kernel, shader};
pub use loss::{ImageLoss, LossOutput};
pub use renderer::Renderer;
pub use scan::PrefixSum;
pub use sort::{RadixSort, SortBuffers};
pub use state::{ForwardState, Gradients, RenderedImage};
