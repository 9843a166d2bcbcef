//! Image-quality metrics in the conventions the deblurring papers report (Deblur-NeRF's
//! `metrics.py`, reused by DP-NeRF, Deblurring-3DGS, BAGS and CoCoGaussian):
//!
//! - [`psnr`] on [0,1];
//! - [`ssim`] in two conventions ([`SsimConvention::DeblurNerf`] for the papers' tables,
//!   [`SsimConvention::Gaussian11`] for the standard Wang et al. value), both matching
//!   scikit-image to ~1e-12;
//! - [`Lpips`] v0.1 (AlexNet or VGG-16) on the CPU, im2col + SIMD sgemm on all cores. Its weights
//!   are installed once by `scripts/lpips/fetch-weights.sh` (see [`weights_dirs`]).
//!
//! [`evaluate_dirs`] scores a folder of predictions against a folder of ground truths (matched by
//! file stem) into a [`Report`] (`metrics.json`), and [`format_table`] renders one for a terminal.

mod error;
mod image;
pub mod lpips;
mod pairs;
mod report;
mod ssim;
mod table;

pub use error::MetricsError;
pub use image::{FloatImage, load_image};
pub use lpips::{Lpips, Net, WEIGHTS_ENV, find_weights, find_weights_in, weights_dirs};
pub use pairs::{IMAGE_EXTENSIONS, ImagePair, pair_dirs};
pub use report::{
    EvalOptions, ImageScores, LpipsMode, LpipsStatus, Models, Observer, REPORT_FORMAT,
    REPORT_VERSION, Report, Scores, evaluate_dirs, score_pair, write_json_atomic,
};
pub use ssim::{SsimConvention, psnr, ssim};
pub use table::format_table;
