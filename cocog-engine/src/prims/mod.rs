//! Data-parallel building blocks that know nothing of Gaussians: prefix sum, radix sort, the
//! Adam step and the L1 + D-SSIM image loss.

mod adam;
mod loss;
mod scan;
mod sort;

pub use adam::{Adam, AdamConfig, AdamMoments};
pub use loss::{ImageLoss, LossOutput, LossValue};
pub use scan::PrefixSum;
pub use sort::{RadixSort, SortBuffers, SortCount};
