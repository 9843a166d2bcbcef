//! The stage's training loop: steps, the log, progress, and checkpoints that survive Ctrl-C.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::time::Instant;

use cocog_pipeline::atomic::Staging;
use cocog_pipeline::{Context, StageError};
use serde_json::json;

use super::Plan;
use crate::{DROP_DB, DropWatch, PsnrDrop, Trainer};

/// A run in progress and where its side products go.
pub(super) struct Session<'c> {
    pub trainer: Trainer<'c>,
    downscale: u32,
    iterations: u32,
    views: usize,
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
    /// The most recent fall of the smoothed training PSNR by more than `DROP_DB` (a collapse).
    pub last_drop: Option<PsnrDrop>,
}

impl<'c> Session<'c> {
    pub fn new(trainer: Trainer<'c>, plan: &Plan, output: &Path) -> Result<Self, StageError> {
        let log_path = output.join("train-log.jsonl");
        let file = File::create(&log_path).map_err(|e| StageError::io(&log_path, e))?;
        Ok(Self {
            views: trainer.num_views(),
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
        let mut watch = DropWatch::new(self.views);
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
                // Flushed line by line: `tail -f` shows progress, and a killed run's log
                // still says how far it got.
                writeln!(self.log, "{line}")
                    .and_then(|()| self.log.flush())
                    .map_err(|e| StageError::io(&self.log_path, e))?;
                if let Some(drop) = psnr.and_then(|p| watch.observe(it, p)) {
                    ctx.warn(&drop_message(&drop));
                }
                // Every reading goes to the log file; every fifth to the terminal.
                let every = 5 * self.trainer.config().loss_every.max(1);
                if it % every == 0 || it == total {
                    ctx.info(&format!(
                        "iteration {it}/{total}: loss {loss:.5}, PSNR {:.2} dB, {} Gaussians, \
                     {rate:.1} it/s",
                        psnr.unwrap_or(f64::NAN),
                        stats.num_gaussians
                    ));
                }
            }
            let due = self.checkpoint_every > 0 && it % self.checkpoint_every == 0 && it < total;
            if let Some(dir) = self.checkpoint_dir.clone().filter(|_| due) {
                self.save(&dir)?;
            }
        }
        let seconds = start.elapsed().as_secs_f64();
        let outcome = Outcome {
            final_loss: last.0,
            final_psnr: last.1,
            seconds,
            it_per_s: f64::from(total - first + 1) / seconds.max(1e-9),
            last_drop: watch.last(),
        };
        let summary = json!({
            "summary": {
                "iterations": total,
                "final_loss": outcome.final_loss,
                "final_psnr": outcome.final_psnr,
                "seconds": seconds,
                "it_per_s": outcome.it_per_s,
                "last_psnr_drop": outcome.last_drop.map(|d| d.iteration),
            }
        });
        writeln!(self.log, "{summary}").map_err(|e| StageError::io(&self.log_path, e))?;
        self.log
            .flush()
            .map_err(|e| StageError::io(&self.log_path, e))?;
        match &outcome.last_drop {
            Some(d) => ctx.warn(&format!(
                "training PSNR last fell more than {DROP_DB} dB at iteration {} ({:.2} dB, best \
                 {:.2} dB at {}); see train-log.jsonl",
                d.iteration, d.smoothed, d.best, d.best_iteration
            )),
            None => ctx.info(&format!(
                "training PSNR never fell more than {DROP_DB} dB below its best"
            )),
        }
        Ok(outcome)
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

    /// The final state into the output's `checkpoint/`. The in-progress one is then stale,
    /// but the runner removes it only once the output is in place (the stage's summary says
    /// `checkpoint_superseded`): if that last rename failed, the run could still resume.
    pub fn save_final(&self, dir: &Path) -> Result<(), StageError> {
        let state = self
            .trainer
            .snapshot(self.downscale)
            .map_err(StageError::other)?;
        state.save(dir).map_err(StageError::other)?;
        Ok(())
    }
}

fn drop_message(d: &PsnrDrop) -> String {
    format!(
        "iteration {}: training PSNR (mean of the last readings) fell to {:.2} dB, more than \
         {DROP_DB} dB below its best {:.2} dB at iteration {}; if it does not recover, the \
         density schedule does not suit this scene (see `cocog train --help`, --schedule)",
        d.iteration, d.smoothed, d.best, d.best_iteration
    )
}
