//! Procedural synthetic *defocus* datasets in the Deblur-NeRF layout, for `cocog demo` and for
//! end-to-end tests that must make their own data.
//!
//! A tabletop of coloured Gaussians is rendered with the engine's f64 reference splatter.
//! Train views (`index % hold != 0`) go through a thin lens with a per-view focus distance;
//! test views are all in focus. Poses are exact and written three ways (COLMAP text, LLFF
//! `poses_bounds.npy`, `transforms.json`); `lens.json` records the true lens of every view.

mod files;
pub mod lens;
pub mod rig;
mod rng;
pub mod scene;
pub mod sparse;
pub mod workload;
mod write;

use std::path::PathBuf;
use std::time::Duration;

pub use lens::{BlurSpace, ThinLens, render_thin_lens};
pub use rig::{Split, ViewSpec, view_specs};
pub use scene::{Scene, SceneBuilder, tabletop};
pub use write::write_defocus_dataset;

/// What to generate. `Default` is the `cocog demo` dataset.
#[derive(Clone, Debug, PartialEq)]
pub struct SynthConfig {
    /// Drives the scene's layout and colours, the camera jitter and the focus distances.
    pub seed: u64,
    pub views: usize,
    pub width: u32,
    pub height: u32,
    /// Test views are `index % hold == 0` (written as the `hold=<hold>` marker).
    pub hold: usize,
    pub fov_x_deg: f64,
    /// Radius of the disk aperture of the train views, in scene units.
    pub aperture_radius: f64,
    /// Train focus distances are drawn from this range (scene units along the optical axis).
    pub focus_range: [f64; 2],
    /// Pinhole renders averaged per defocused view.
    pub lens_samples: usize,
    /// Gaussians tried as COLMAP points (those seen by fewer than two train views are dropped).
    pub max_points: usize,
    pub blur_space: BlurSpace,
    /// Worker threads; 0 uses every available core.
    pub threads: usize,
}

impl Default for SynthConfig {
    fn default() -> Self {
        Self {
            seed: 0,
            views: 16,
            // 160×120 took ~25 s of CPU in a dev build (the reference splatter visits every
            // Gaussian over a tile for every pixel); 128×96 with 24 lens samples is ~2.5× less.
            width: 128,
            height: 96,
            hold: 8,
            fov_x_deg: 60.0,
            // CoC up to ~7 px at 128 px wide, about the bench's 20 px at 400.
            aperture_radius: 0.025,
            focus_range: [0.65, 2.8],
            lens_samples: 24,
            max_points: 1000,
            blur_space: BlurSpace::Linear,
            threads: 0,
        }
    }
}

impl SynthConfig {
    /// A few tiny views for tests: same scene, far fewer pixels and lens samples.
    pub fn tiny(seed: u64) -> Self {
        Self {
            seed,
            views: 10,
            width: 48,
            height: 36,
            lens_samples: 12,
            max_points: 200,
            // A larger aperture keeps the CoC (in pixels) near the default's at this size.
            aperture_radius: 0.05,
            ..Self::default()
        }
    }

    pub fn validate(&self) -> Result<(), SynthError> {
        let bad = |m: String| Err(SynthError::Config(m));
        if !(2..=1000).contains(&self.views) {
            return bad(format!(
                "views must be 2..=1000 (NNN.png names), got {}",
                self.views
            ));
        }
        if self.hold < 2 {
            return bad(format!(
                "hold must be at least 2 so there are train views, got {}",
                self.hold
            ));
        }
        if !(8..=4096).contains(&self.width) || !(8..=4096).contains(&self.height) {
            return bad(format!(
                "image size must be 8..=4096 per side, got {}x{}",
                self.width, self.height
            ));
        }
        if !(self.fov_x_deg > 1.0 && self.fov_x_deg < 150.0) {
            return bad(format!(
                "fov_x_deg must be in (1, 150), got {}",
                self.fov_x_deg
            ));
        }
        if !(self.aperture_radius.is_finite() && self.aperture_radius >= 0.0) {
            return bad(format!(
                "aperture_radius must be finite and >= 0, got {}",
                self.aperture_radius
            ));
        }
        let [lo, hi] = self.focus_range;
        if !(lo.is_finite() && hi.is_finite() && lo > 0.0 && lo <= hi) {
            return bad(format!(
                "focus_range must satisfy 0 < near <= far, got {:?}",
                self.focus_range
            ));
        }
        if !(1..=1024).contains(&self.lens_samples) {
            return bad(format!(
                "lens_samples must be 1..=1024, got {}",
                self.lens_samples
            ));
        }
        Ok(())
    }
}

/// What was generated.
#[derive(Clone, Debug, PartialEq)]
pub struct SynthSummary {
    pub dir: PathBuf,
    pub views: usize,
    pub train_views: usize,
    pub test_views: usize,
    pub width: u32,
    pub height: u32,
    /// Per view in file order; `None` for the all-in-focus test views.
    pub focus_distances: Vec<Option<f64>>,
    pub gaussians: usize,
    pub points: usize,
    pub elapsed: Duration,
}

#[derive(Debug, thiserror::Error)]
pub enum SynthError {
    #[error("{0}: already exists; choose a new directory (datasets are never overwritten)")]
    Exists(PathBuf),
    #[error("invalid synth config: {0}")]
    Config(String),
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error(transparent)]
    Format(#[from] cocog_formats::FormatError),
    #[error("{path}: cannot write PNG: {source}")]
    Image {
        path: PathBuf,
        #[source]
        source: image::ImageError,
    },
    #[error("{path}: cannot serialise JSON: {message}")]
    Json { path: PathBuf, message: String },
}

pub(crate) fn io_err(path: &std::path::Path) -> impl Fn(std::io::Error) -> SynthError + '_ {
    move |source| SynthError::Io {
        path: path.to_owned(),
        source,
    }
}
