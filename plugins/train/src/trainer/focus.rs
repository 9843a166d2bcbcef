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

impl<'c> Trainer<'c> {
    /// Replaces each training photo's learned focus distance by a fresh estimate against the
    /// current base Gaussians (views without one keep theirs). The first Adam moment restarts
    /// at 0 so the old direction does not carry the focus back; the second keeps the
    /// gradient's scale.
    pub(super) fn refocus(&mut self) -> Result<(), TrainError> {
        let found = self.estimate_focus()?;
        let ctx = self.ctx;
        let Some(focus) = self.coc.as_ref().and_then(|c| c.focus.as_ref()) else {
            return Ok(());
        };
        for (v, d) in found.iter().enumerate() {
            if !(d.is_finite() && *d > 0.0) {
                continue;
            }
            let at = (v * std::mem::size_of::<f32>()) as u64;
            let value = (*d / f64::from(focus.scale)) as f32;
            ctx.queue
                .write_buffer(&focus.values, at, bytemuck::bytes_of(&value));
            ctx.queue
                .write_buffer(&focus.moments.m, at, bytemuck::bytes_of(&0.0f32));
        }
        Ok(())
    }
}
