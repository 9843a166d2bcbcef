//! Gaussian splatting proper: batches of parameters and cameras, the forward rasterizer and
//! its backward pass.

mod batch;
mod frame;
mod renderer;
mod state;

pub use batch::{
    Batch, Crop, ImageSpec, ParamBuffers, bytes_per_gaussian, check_fits, check_fits_at,
};
pub use frame::Frame;
pub use renderer::{
    FINITE_WGSL, MAX_SPLIT, QUAT_TO_ROT_WGSL, RasterBlocks, RasterSplit, Renderer, SCAN_WIDTH,
    SPLIT_TARGET, raster_split_for,
};
pub use state::{ForwardState, Gradients, RenderedImage};
