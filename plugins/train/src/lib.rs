//! cocog-train: the vanilla 3DGS training loop (INRIA 2023) on the cocog GPU engine.
//!
//! `init_from_points` turns a point cloud into Gaussians by the INRIA rule, `scene_extent`
//! gives the scale the position learning rate is relative to, and `Trainer` runs
//! forward → (1 − λ)·L1 + λ·D-SSIM → backward → per-group Adam, one view per iteration in a
//! seeded order, raising the SH degree every `sh_degree_interval` iterations. Everything but
//! Deblurring 3DGS's point addition stays on the GPU, densification and SH growth included;
//! losses and densified counts come back asynchronously, a few steps late.
//!
//! Determinism: the initialisation and the view order depend only on the inputs and the seed.
//! The GPU backward accumulates gradients with float atomics, whose summation order varies,
//! so parameters agree between runs only to rounding.

mod add_points;
mod bench;
mod checkpoint;
mod coc_config;
mod config;
mod densify;
mod densify_gpu;
mod drop_watch;
mod error;
mod focus_estimate;
mod init;
mod order;
mod scale;
mod stage;
mod stats;
mod trainer;

pub use add_points::{PointsFrame, add_points, box_volume, candidate_count, colmap_unit};
pub use bench::{
    BenchOptions, BenchReport, KernelMs, PhaseMs, SyntheticSpec, run_bench, run_bench_synthetic,
};
pub use checkpoint::{
    CHECKPOINT_FILE, CheckpointError, CocCheckpoint, FocusState, MomentState, TrainState,
};
pub use coc_config::CocTrainConfig;
pub use config::TrainConfig;
pub use densify::{
    DensifyConfig, DensifyPlan, DepthAxis, Origin, SplitNoise, apply_plan, gather_rows,
    plan_densify,
};
pub use densify_gpu::{BURIED_LOG_SCALE, BURIED_OPACITY_LOGIT, DensifyInputs, GpuDensify};
pub use drop_watch::{DROP_DB, DropWatch, PsnrDrop};
pub use error::TrainError;
pub use init::{SH_C0, init_from_points, inverse_sigmoid, rgb_to_sh, scene_extent};
pub use order::{SplitMix64, ViewOrder};
pub use scale::{depth_scene_scale, median_depth};
pub use stage::Train;
pub use stats::GradStats;
pub use trainer::{
    PhaseTimes, Reading, StepStats, TrainView, Trainer, record_widen_sh, widen_kernel, widen_sh,
};

/// The stages this crate provides to the pipeline host.
pub fn stages() -> Vec<Box<dyn cocog_pipeline::Stage>> {
    vec![Box::new(Train)]
}
