//! Data-parallel building blocks that know nothing of Gaussians: prefix sum, radix sort, the
//! Adam step, the L1 + D-SSIM image loss, a tiled matrix product for the networks, and a sum of
//! gradients computed in pieces.

mod adam;
mod add;
mod gemm;
mod loss;
mod scan;
mod sort;

pub use adam::{Adam, AdamConfig, AdamMoments};
pub use add::AddInto;
pub use gemm::{CoopBlock, Gemm, GemmLayout, GemmShape, GemmTile, OperandScales};
pub use loss::{ImageLoss, LossOutput, LossRows, LossValue};
pub use scan::PrefixSum;
pub use sort::{RadixSort, SortBuffers, SortCount};
