//! f64 CPU reference of the whole engine. It is deliberately simple (no tiling tricks beyond
//! what changes results) so it can validate the GPU kernels and be finite-differenced.

// Index loops mirror the matrix formulas they implement; iterator chains would hide them.
#![allow(clippy::needless_range_loop)]

pub mod loss;
mod project;
mod raster;
pub mod sh;

pub use project::{Projected, ProjectedGrad, project, project_backward, quat_to_rot};
pub use raster::{Image64, raster_backward, render, render_backward};

use crate::types::{GaussianGrads, GaussianParams};

/// `GaussianParams` in f64, so finite differences are meaningful.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Gaussians64 {
    pub sh_degree: u32,
    pub means: Vec<[f64; 3]>,
    pub log_scales: Vec<[f64; 3]>,
    pub quats: Vec<[f64; 4]>,
    pub opacity_logits: Vec<f64>,
    pub sh: Vec<f64>,
}

impl From<&GaussianParams> for Gaussians64 {
    fn from(p: &GaussianParams) -> Self {
        Self {
            sh_degree: p.sh_degree,
            means: p.means.iter().map(|v| v.map(f64::from)).collect(),
            log_scales: p.log_scales.iter().map(|v| v.map(f64::from)).collect(),
            quats: p.quats.iter().map(|v| v.map(f64::from)).collect(),
            opacity_logits: p.opacity_logits.iter().map(|&v| f64::from(v)).collect(),
            sh: p.sh.iter().map(|&v| f64::from(v)).collect(),
        }
    }
}

impl Gaussians64 {
    pub fn len(&self) -> usize {
        self.means.len()
    }

    pub fn is_empty(&self) -> bool {
        self.means.is_empty()
    }

    /// Every scalar parameter in a fixed order, for finite differencing: `(name, value)`.
    pub fn scalars_mut(&mut self) -> Vec<(&'static str, &mut f64)> {
        let mut out: Vec<(&'static str, &mut f64)> = Vec::new();
        out.extend(self.means.iter_mut().flatten().map(|v| ("means", v)));
        out.extend(
            self.log_scales
                .iter_mut()
                .flatten()
                .map(|v| ("log_scales", v)),
        );
        out.extend(self.quats.iter_mut().flatten().map(|v| ("quats", v)));
        out.extend(
            self.opacity_logits
                .iter_mut()
                .map(|v| ("opacity_logits", v)),
        );
        out.extend(self.sh.iter_mut().map(|v| ("sh", v)));
        out
    }
}

/// Gradients in the layout of `Gaussians64`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Grads64 {
    pub v_means: Vec<[f64; 3]>,
    pub v_log_scales: Vec<[f64; 3]>,
    pub v_quats: Vec<[f64; 4]>,
    pub v_opacity_logits: Vec<f64>,
    pub v_sh: Vec<f64>,
}

impl Grads64 {
    pub fn zeros_like(g: &Gaussians64) -> Self {
        Self {
            v_means: vec![[0.0; 3]; g.len()],
            v_log_scales: vec![[0.0; 3]; g.len()],
            v_quats: vec![[0.0; 4]; g.len()],
            v_opacity_logits: vec![0.0; g.len()],
            v_sh: vec![0.0; g.sh.len()],
        }
    }

    /// Same order as `Gaussians64::scalars_mut`.
    pub fn scalars(&self) -> Vec<f64> {
        let mut out = Vec::new();
        out.extend(self.v_means.iter().flatten());
        out.extend(self.v_log_scales.iter().flatten());
        out.extend(self.v_quats.iter().flatten());
        out.extend(&self.v_opacity_logits);
        out.extend(&self.v_sh);
        out
    }
}

impl GaussianGrads {
    /// Same order as `Gaussians64::scalars_mut`, widened to f64 for comparisons.
    pub fn scalars(&self) -> Vec<f64> {
        let mut out: Vec<f64> = Vec::new();
        out.extend(self.v_means.iter().flatten().map(|&v| f64::from(v)));
        out.extend(self.v_log_scales.iter().flatten().map(|&v| f64::from(v)));
        out.extend(self.v_quats.iter().flatten().map(|&v| f64::from(v)));
        out.extend(self.v_opacity_logits.iter().map(|&v| f64::from(v)));
        out.extend(self.v_sh.iter().map(|&v| f64::from(v)));
        out
    }
}
