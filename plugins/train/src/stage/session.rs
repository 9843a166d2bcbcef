//! The stage's training loop: steps, the log, progress, and checkpoints that survive Ctrl-C.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::time::Instant;

use cocog_pipeline::atomic::Staging;
use cocog_pipeline::{Context, StageError};
use serde_json::json;

use super::Plan;
use crate::Trainer;

/// A run in progress and where its side products go.
pub(super) struct Session<'c> {
    pub trainer: Trainer<'c>,
    downscale: u32,
    iterations: u32,
    checkpoint_dir: Option<PathBuf>,
    checkpoint_every: u32,
    log_path: PathBuf,
    log: BufWriter<File>,
}

/// How the loop ended.
pub(super) struct Outcome {
    pub final_loss: Option<f64>,
    pub final_psnr: Option<f64>,
    pub seconds: f64,
    pub it_per_s: f64,
}

impl<'c> Session<'c> {
    pub fn new(trainer: Trainer<'c>, plan: &Plan, output: &Path) -> Result<Self, StageError> {
        let log_path = output.join("train-log.jsonl");
        let file = File::create(&log_path).map_err(|e| StageError::io(&log_path, e))?;
        Ok(Self {
            trainer,
            downscale: plan.downscale,
            iterations: plan.config.iterations,
            checkpoint_dir: plan.checkpoint_dir.clone(),
            checkpoint_every: plan.checkpoint_every,
            log_path,
            log: BufWriter::new(file),
        })
    }

    pub fn run(&mut self, ctx: &dyn Context) -> Result<Outcome, StageError> {
        let first = self.trainer.iteration() + 1;
        let total = self.iterations;
        let start = Instant::now();
        let mut last = (None, None);
        for it in first..=total {
            if ctx.cancelled() {
                self.save_on_interrupt(ctx)?;
                return Err(StageError::Cancelled);
            }
            let stats = self.trainer.step().map_err(StageError::other)?;
            if it % 10 == 0 || it == total || it == first {
                ctx.progress("train", u64::from(it), u64::from(total));
            }
            if let (Some(loss), psnr) = (stats.loss, stats.psnr) {
                last = (Some(loss), psnr);
                let elapsed = start.elapsed().as_secs_f64();
                let rate = f64::from(it - first + 1) / elapsed.max(1e-9);
                let line = json!({
                    "iteration": it,
                    "loss": loss,
                    "psnr": psnr,
                    "gaussians": stats.num_gaussians,
                    "sh_degree": stats.sh_degree,
                    "elapsed_s": elapsed,
                    "it_per_s": rate,
                });
                writeln!(self.log, "{line}").map_err(|e| StageError::io(&self.log_path, e))?;
                ctx.info(&format!(
                    "iteration {it}/{total}: loss {loss:.5}, PSNR {:.2} dB, {} Gaussians, \
                     {rate:.1} it/s",
                    psnr.unwrap_or(f64::NAN),
                    stats.num_gaussians
                ));
            }
            let due = self.checkpoint_every > 0 && it % self.checkpoint_every == 0 && it < total;
            if let Some(dir) = self.checkpoint_dir.clone().filter(|_| due) {
                self.save(&dir)?;
            }
        }
        self.log
            .flush()
            .map_err(|e| StageError::io(&self.log_path, e))?;
        let seconds = start.elapsed().as_secs_f64();
        Ok(Outcome {
            final_loss: last.0,
            final_psnr: last.1,
            seconds,
            it_per_s: f64::from(total - first + 1) / seconds.max(1e-9),
        })
    }

    /// Replaces `dir` with the current state, atomically: an interruption while writing
    /// leaves the previous checkpoint.
    fn save(&self, dir: &Path) -> Result<(), StageError> {
        let state = self
            .trainer
            .snapshot(self.downscale)
            .map_err(StageError::other)?;
        let staging = Staging::beside(dir);
        state.save(staging.path()).map_err(StageError::other)?;
        staging
            .commit(dir, true)
            .map_err(|e| StageError::io(dir, e))
    }

    fn save_on_interrupt(&self, ctx: &dyn Context) -> Result<(), StageError> {
        let Some(dir) = &self.checkpoint_dir else {
            return Ok(());
        };
        if self.trainer.iteration() == 0 {
            return Ok(());
        }
        self.save(dir)?;
        ctx.warn(&format!(
            "interrupted after iteration {}; checkpoint saved to {} (continue with --resume {})",
            self.trainer.iteration(),
            dir.display(),
            dir.display()
        ));
        Ok(())
    }

    /// The final state into the output's `checkpoint/`; the in-progress one is then stale.
    pub fn save_final(&self, dir: &Path) -> Result<(), StageError> {
        let state = self
            .trainer
            .snapshot(self.downscale)
            .map_err(StageError::other)?;
        state.save(dir).map_err(StageError::other)?;
        if let Some(stale) = self.checkpoint_dir.as_ref().filter(|d| d.exists()) {
            std::fs::remove_dir_all(stale).map_err(|e| StageError::io(stale, e))?;
        }
        Ok(())
    }
}
