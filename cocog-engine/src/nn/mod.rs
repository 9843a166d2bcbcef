//! CoCoGaussian's compositor F (method.md §5): three convolutions (5×5 3→C, 3×3 C→C, each with
//! ReLU and InstanceNorm, then a 3×3 C→1 head) turn each of the M + 1 renders of a view into
//! per-pixel logits; a softmax over the renders weighs their sum. F sees the renders detached,
//! so the renders' gradient comes only through that product. Before F starts training the
//! renders are averaged (`CompositeMode::Uniform`).
//!
//! The convolutions are direct (one thread per output value); tiled implicit-GEMM kernels with
//! f16 storage are the planned speed-up for full-resolution photos.

mod composite;
mod layout;
pub mod reference;

pub use composite::{CompositeGrads, CompositeMode, CompositeOutput, Compositor};
pub use layout::{CompositorConfig, CompositorLayout, IN_EPS};
