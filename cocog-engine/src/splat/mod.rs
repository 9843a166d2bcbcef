//! Gaussian splatting proper: batches of parameters and cameras, the forward rasterizer and
//! its backward pass.

mod batch;
mod renderer;
mod state;

pub use batch::{Batch, ImageSpec, ParamBuffers};
pub use renderer::Renderer;
pub use state::{ForwardState, Gradients, RenderedImage};
