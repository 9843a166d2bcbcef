//! The focus distances' start by depth from defocus (`focus_estimate.rs`), from the warm-up
//! Gaussians at the blur start.

use super::Trainer;
use crate::TrainError;
use crate::focus_estimate::{FocusEvidence, estimate_focus};

impl<'c> Trainer<'c> {
    /// Per training view, the focus distance that best explains its photo as the current
    /// Gaussians seen through a thin lens; NaN where the view saw too little to say (its start
    /// then falls back to the mean distance).
    pub(super) fn estimate_focus(&mut self) -> Result<Vec<f64>, TrainError> {
        let cameras = self.cameras.clone();
        let mut found = Vec::with_capacity(cameras.len());
        for (v, cam) in cameras.iter().enumerate() {
            let seen = self.render(cam)?;
            let (w, h) = (cam.width as usize, cam.height as usize);
            let target: Vec<[f32; 4]> = self.ctx.read(&self.targets[v], w * h)?;
            let photo: Vec<[f32; 3]> = target.iter().map(|p| [p[0], p[1], p[2]]).collect();
            // The CoC follows the distance from the camera centre (method.md §3.1), and the
            // renderer's depth is alpha-weighted z along the optical axis.
            let distance: Vec<f32> = (0..w * h)
                .map(|i| {
                    let alpha = seen.alpha[i];
                    if alpha < 0.5 {
                        return 0.0;
                    }
                    let x = ((i % w) as f64 + 0.5 - cam.cx) / cam.fx;
                    let y = ((i / w) as f64 + 0.5 - cam.cy) / cam.fy;
                    (f64::from(seen.depth[i] / alpha) * (1.0 + x * x + y * y).sqrt()) as f32
                })
                .collect();
            let evidence = FocusEvidence {
                photo: &photo,
                render: &seen.color,
                distance: &distance,
                width: w,
                height: h,
            };
            found.push(estimate_focus(&evidence).unwrap_or(f64::NAN));
        }
        Ok(found)
    }
}
