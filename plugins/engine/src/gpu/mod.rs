//! The wgpu side of the engine.

mod buffers;
mod context;
mod kernel;
mod scan;
mod sort;

pub use buffers::{GpuBuffer, MemoryTracker};
pub use context::GpuContext;
pub use scan::PrefixSum;
pub use sort::{RadixSort, Sorted};
