//! Circle-of-confusion Gaussians (method.md §3–§4): the MLP h_θ, the expansion of base
//! Gaussians into M CoC copies plus the base set, and its adjoint.
//!
//! Per training view, every base Gaussian i is fed to h_θ with the view's camera centre; its
//! heads say where the M copies sit and how much they grow. The expanded sets are laid out
//! `[set][base]` (set M is the base set itself, modulated in scale and rotation as in the
//! released code), so one rasterizer launch renders all M + 1 images. Copies share opacity and
//! SH with their base. The adjoint sums the sets' gradients back into the base Gaussians, and
//! yields the gradients of h_θ's weights and of the view's focus distance.
//!
//! Rotations: the sets carry q/|q| ⊙ δq. The released code feeds that unnormalised product to
//! a rasterizer that does not renormalise, so δq also stretches; this rasterizer renormalises,
//! so δq only turns the copy, and growth comes from δs alone.

mod gpu;
mod layout;
mod mlp;
pub mod reference;
mod refocus;

pub use gpu::{CocExpansion, CocGrads, CocKernels, CocStep};
pub use layout::{
    CAMERA_DIM, CocConfig, CocVariant, HeadLayout, INPUT_DIM, MEAN_DIM, MlpLayout, ROW_DIM,
    init_weights,
};
pub use mlp::MlpActivations;
pub use refocus::{Frame, Lens, Refocus};
