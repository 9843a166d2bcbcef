//! CoCoGaussian's compositor F (method.md §5): three convolutions (5×5 3→C, 3×3 C→C, each with
//! ReLU and InstanceNorm, then a 3×3 C→1 head) turn each of the M + 1 renders of a view into
//! per-pixel logits; a softmax over the renders weighs their sum. F sees the renders detached,
//! so the renders' gradient comes only through that product. Before F starts training the
//! renders are averaged (`CompositeMode::Uniform`).
//!
//! The C-channel convolutions run as tiled implicit GEMMs (conv_gemm.rs), or their forwards and
//! input gradients as spatially tiled direct convolutions (conv_tile.rs), or the 3×3 layer by
//! Winograd's minimal filtering (conv_winograd.rs; `ConvPath` picks); the
//! one-channel head, a sliver of the work, as direct kernels. The forward maps are stored in
//! half precision where the adapter allows (precision.rs).

mod composite;
mod conv_gemm;
mod conv_tile;
mod conv_winograd;
mod layout;
mod precision;
pub mod reference;

pub use composite::{
    CompositeGrads, CompositeMode, CompositeOutput, Compositor, ConvPath, direct_first_forward,
};
pub use layout::{CompositorConfig, CompositorLayout, IN_EPS};
pub use precision::MapPrecision;
