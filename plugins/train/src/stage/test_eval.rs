//! `eval_every`: the held-out views scored while training, so a run can be watched for
//! overfitting, not only for its training loss.

use std::time::Instant;

use cocog_metrics::{FloatImage, SsimConvention, psnr, ssim};
use cocog_pipeline::{Context, Scene, Split, StageError, StageRequest};
use serde_json::{Value, json};

use crate::{TrainConfig, TrainView, Trainer};

/// The test split at the training resolution, as the trainer's targets are.
pub(super) struct TestViews(Vec<TrainView>);

/// Mean scores over the test views.
pub(super) struct Scores {
    pub iteration: u32,
    pub views: usize,
    pub psnr: f64,
    /// `None` when a view is smaller than SSIM's window.
    pub ssim: Option<f64>,
    pub seconds: f64,
}

impl TestViews {
    pub fn load(
        scene: &Scene,
        req: &StageRequest,
        downscale: u32,
        config: &TrainConfig,
        ctx: &dyn Context,
    ) -> Result<Self, StageError> {
        let views = super::load::views_scratch(scene, req, Split::Test, downscale, config, ctx)?;
        if views.is_empty() {
            return Err(StageError::Options(format!(
                "option 'eval_every': {} has no test views to score (ingest with --hold N to \
                 hold some out)",
                req.input.display()
            )));
        }
        Ok(Self(views))
    }

    pub fn len(&self) -> usize {
        self.0.len()
    }

    /// Renders every test view with the current Gaussians and scores it as `cocog eval`
    /// does: the render quantised to 8 bits like a PNG, PSNR, and SSIM in the Deblur-NeRF
    /// convention (the papers' tables).
    pub fn score(&self, trainer: &mut Trainer<'_>) -> Result<Scores, StageError> {
        let started = Instant::now();
        let (mut psnr_sum, mut ssim_sum, mut ssim_ok) = (0.0, 0.0, true);
        for view in &self.0 {
            let rendered = trainer.render(&view.camera).map_err(StageError::other)?;
            let (w, h) = (view.camera.width, view.camera.height);
            let pred = float_image(w, h, rendered.color.iter().map(|c| quantise(*c)));
            let truth = float_image(w, h, view.image.iter().copied());
            psnr_sum += psnr(&pred, &truth);
            match ssim(&pred, &truth, SsimConvention::DeblurNerf) {
                Some(s) => ssim_sum += s,
                None => ssim_ok = false,
            }
        }
        let n = self.0.len() as f64;
        Ok(Scores {
            iteration: trainer.iteration(),
            views: self.0.len(),
            psnr: psnr_sum / n,
            ssim: ssim_ok.then_some(ssim_sum / n),
            seconds: started.elapsed().as_secs_f64(),
        })
    }
}

impl Scores {
    /// The log record: its own kind, apart from the training-view readings.
    pub fn record(&self) -> Value {
        json!({ "eval": {
            "iteration": self.iteration,
            "split": "test",
            "views": self.views,
            "psnr": self.psnr,
            "ssim": self.ssim,
            "seconds": self.seconds,
        }})
    }

    pub fn line(&self) -> String {
        let ssim = self
            .ssim
            .map_or(String::new(), |s| format!(", SSIM {s:.4}"));
        format!(
            "iteration {}: test views PSNR {:.2} dB{ssim} ({} views, {:.1} s)",
            self.iteration, self.psnr, self.views, self.seconds
        )
    }
}

fn quantise(c: [f32; 3]) -> [f32; 3] {
    c.map(|v| (v.clamp(0.0, 1.0) * 255.0).round() / 255.0)
}

fn float_image(width: u32, height: u32, pixels: impl Iterator<Item = [f32; 3]>) -> FloatImage {
    FloatImage {
        width,
        height,
        data: pixels.flatten().map(f64::from).collect(),
    }
}
