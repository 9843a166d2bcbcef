//! Hyper-parameters of the vanilla 3DGS optimisation (INRIA 2023 defaults).

use crate::{CocTrainConfig, DensifyConfig};

/// Learning rates and schedules. Defaults are the INRIA `OptimizationParams` of the 2023
/// release (method.md §7), which CoCoGaussian inherits.
#[derive(Clone, Debug, PartialEq)]
pub struct TrainConfig {
    /// Length of the run; the position learning rate decays over exactly this many steps.
    pub iterations: u32,
    /// Position learning rate at step 0 and at `iterations`, both × the scene scale.
    pub position_lr_init: f64,
    pub position_lr_final: f64,
    /// SH DC learning rate; the higher-order coefficients use it / 20.
    pub feature_lr: f32,
    pub opacity_lr: f32,
    pub scaling_lr: f32,
    pub rotation_lr: f32,
    /// λ of (1 − λ)·L1 + λ·D-SSIM.
    pub lambda_dssim: f32,
    /// The active SH degree rises by one every this many iterations, up to `max_sh_degree`.
    pub sh_degree_interval: u32,
    pub max_sh_degree: u32,
    pub background: [f32; 3],
    /// Composite each training render over a random colour instead (INRIA's
    /// `--random_background`): transparency can no longer pass for a matching background,
    /// which keeps floaters' opacity honest. Evaluation renders keep `background`.
    pub random_background: bool,
    /// Seeds the view order.
    pub seed: u64,
    /// Read the loss back (one GPU→CPU sync) every this many iterations; 0 never.
    pub loss_every: u32,
    /// Adaptive density control; `None` trains a fixed set of Gaussians.
    pub densify: Option<DensifyConfig>,
    /// The length (scene units) that the position learning rate and the world-space density
    /// rules scale with; `None` takes INRIA's camera extent (`scene_extent`).
    pub scene_scale: Option<f64>,
    /// CoCoGaussian on top of this schedule; `None` is plain 3DGS.
    pub coc: Option<CocTrainConfig>,
}

impl Default for TrainConfig {
    fn default() -> Self {
        Self {
            iterations: 30_000,
            position_lr_init: 1.6e-4,
            position_lr_final: 1.6e-6,
            feature_lr: 2.5e-3,
            opacity_lr: 0.05,
            scaling_lr: 5e-3,
            rotation_lr: 1e-3,
            lambda_dssim: 0.2,
            sh_degree_interval: 1000,
            max_sh_degree: 3,
            background: [0.0; 3],
            random_background: false,
            seed: 0,
            loss_every: 100,
            densify: Some(DensifyConfig::default()),
            scene_scale: None,
            coc: None,
        }
    }
}

impl TrainConfig {
    /// INRIA's `get_expon_lr_func` (no delay): log-linear from init to final × extent over
    /// `iterations`, held at the final value afterwards.
    pub fn position_lr(&self, step: u32, extent: f64) -> f32 {
        let t = (f64::from(step) / f64::from(self.iterations.max(1))).clamp(0.0, 1.0);
        let log_lr = self.position_lr_init.ln() * (1.0 - t) + self.position_lr_final.ln() * t;
        (log_lr.exp() * extent) as f32
    }

    /// SH learning rate of the higher-order coefficients (INRIA: feature_lr / 20).
    pub fn feature_rest_lr(&self) -> f32 {
        self.feature_lr / 20.0
    }

    /// Active SH degree at 1-based iteration `step`: INRIA raises it at the start of every
    /// iteration divisible by the interval.
    pub fn sh_degree_at(&self, step: u32) -> u32 {
        (step / self.sh_degree_interval.max(1)).min(self.max_sh_degree)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn position_lr_decays_exponentially_between_the_inria_endpoints() {
        let c = TrainConfig::default();
        let extent = 2.5;
        assert!((c.position_lr(0, extent) - 1.6e-4 * 2.5).abs() < 1e-9);
        assert!((c.position_lr(30_000, extent) - 1.6e-6 * 2.5).abs() < 1e-11);
        assert!((c.position_lr(90_000, extent) - 1.6e-6 * 2.5).abs() < 1e-11);
        // Half-way is the geometric mean: 1.6e-5 × extent.
        assert!((c.position_lr(15_000, extent) - 1.6e-5 * 2.5).abs() < 1e-9);
    }

    #[test]
    fn sh_degree_grows_every_interval_and_saturates() {
        let c = TrainConfig::default();
        let degrees: Vec<u32> = [1, 999, 1000, 1999, 2000, 3000, 9000]
            .iter()
            .map(|&s| c.sh_degree_at(s))
            .collect();
        assert_eq!(degrees, [0, 0, 1, 1, 2, 3, 3]);
        assert!((c.feature_rest_lr() - 1.25e-4).abs() < 1e-10);
    }
}
