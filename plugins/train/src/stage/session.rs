//! The stage's training loop: steps, the log, progress, test scores, and checkpoints that
//! survive Ctrl-C.

use std::path::{Path, PathBuf};
use std::time::Instant;

use cocog_pipeline::atomic::Staging;
use cocog_pipeline::{Context, StageError};
use serde_json::{Value, json};

use super::Plan;
use super::log::TrainLog;
use super::test_eval::{Scores, TestViews};
use crate::{DROP_DB, DropWatch, PsnrDrop, Reading, TrainError, Trainer};

/// What is wrong when reading `r`'s loss is not a number; `last_finite` is the latest one
/// that was, as (iteration, loss).
fn diverged(r: &Reading, last_finite: Option<(u32, f64)>) -> Option<String> {
    if r.loss.is_finite() {
        return None;
    }
    let last = match last_finite {
        Some((i, l)) => format!("the last finite reading: {l:.5} at iteration {i}"),
        None => "no earlier reading was finite".to_owned(),
    };
    Some(format!(
        "the loss is {} at iteration {} ({last})",
        r.loss, r.iteration
    ))
}

/// A run in progress and where its side products go.
pub(super) struct Session<'c> {
    pub trainer: Trainer<'c>,
    downscale: u32,
    iterations: u32,
    views: usize,
    checkpoint_dir: Option<PathBuf>,
    checkpoint_every: u32,
    log: TrainLog,
    test: Option<TestViews>,
    eval_every: u32,
    /// The latest reading whose loss was a number: (iteration, loss).
    last_finite: Option<(u32, f64)>,
    /// The iteration of the last checkpoint this run saved.
    saved_at: Option<u32>,
}

/// How the loop ended.
pub(super) struct Outcome {
    pub final_loss: Option<f64>,
    pub final_psnr: Option<f64>,
    pub seconds: f64,
    pub it_per_s: f64,
    /// The most recent fall of the smoothed training PSNR by more than `DROP_DB` (a collapse).
    pub last_drop: Option<PsnrDrop>,
    /// The test views' scores at the end, with `eval_every`.
    pub test: Option<Scores>,
}

impl<'c> Session<'c> {
    /// Opens the log (telling the user where it is when it is kept beside the output) and
    /// writes `start`, the run's first record.
    pub fn new(
        trainer: Trainer<'c>,
        plan: &Plan,
        output: &Path,
        test: Option<TestViews>,
        start: &Value,
        ctx: &dyn Context,
    ) -> Result<Self, StageError> {
        let mut log = TrainLog::open(plan.live_log.as_deref(), plan.resume.as_deref(), output)?;
        if plan.live_log.is_some() {
            ctx.info(&format!(
                "training log: {} (follow it with tail -f; it goes into the output as \
                 train-log.jsonl when training succeeds)",
                log.path().display()
            ));
        }
        log.record(&json!({ "start": start }))?;
        Ok(Self {
            views: trainer.num_views(),
            trainer,
            downscale: plan.downscale,
            iterations: plan.config.iterations,
            checkpoint_dir: plan.checkpoint_dir.clone(),
            checkpoint_every: plan.checkpoint_every,
            log,
            test,
            eval_every: plan.eval_every,
            last_finite: None,
            saved_at: None,
        })
    }

    /// Scores the test views if one is due after iteration `it` (every `eval_every` and at
    /// the end); returns the seconds it took, which are not training time.
    fn maybe_eval(
        &mut self,
        it: u32,
        last: &mut Option<Scores>,
        ctx: &dyn Context,
    ) -> Result<f64, StageError> {
        let due =
            self.eval_every > 0 && (it.is_multiple_of(self.eval_every) || it == self.iterations);
        let Some(test) = self.test.as_ref().filter(|_| due) else {
            return Ok(0.0);
        };
        let scores = test.score(&mut self.trainer)?;
        self.log.record(&scores.record())?;
        ctx.info(&scores.line());
        let seconds = scores.seconds;
        *last = Some(scores);
        Ok(seconds)
    }

    /// Logs one reading, watches it for a collapse, and prints every fifth.
    /// `clock` is (run start, first iteration, seconds spent scoring test views).
    fn report(
        &mut self,
        r: &Reading,
        clock: (Instant, u32, f64),
        watch: &mut DropWatch,
        ctx: &dyn Context,
    ) -> Result<(), StageError> {
        let (start, first, eval_seconds) = clock;
        let (it, total) = (r.iteration, self.iterations);
        let elapsed = start.elapsed().as_secs_f64();
        let rate = f64::from(it - first + 1) / (elapsed - eval_seconds).max(1e-9);
        let line = json!({
            "iteration": it,
            "loss": r.loss,
            "psnr": r.psnr,
            "gaussians": r.num_gaussians,
            "sh_degree": r.sh_degree,
            "elapsed_s": elapsed,
            "it_per_s": rate,
        });
        self.log.record(&line)?;
        if let Some(what) = diverged(r, self.last_finite) {
            return Err(self.diverged_error(what));
        }
        self.last_finite = Some((it, r.loss));
        if let Some(drop) = watch.observe(it, r.psnr) {
            ctx.warn(&drop_message(&drop));
        }
        // Every reading goes to the log file; every fifth to the terminal.
        let every = 5 * self.trainer.config().loss_every.max(1);
        if it % every == 0 || it == total {
            ctx.info(&format!(
                "iteration {it}/{total}: loss {:.5}, PSNR {:.2} dB, {} Gaussians, {rate:.1} it/s",
                r.loss, r.psnr, r.num_gaussians
            ));
        }
        Ok(())
    }

    pub fn run(&mut self, ctx: &dyn Context) -> Result<Outcome, StageError> {
        let first = self.trainer.iteration() + 1;
        let total = self.iterations;
        let start = Instant::now();
        let mut last = (None, None);
        let mut last_test = None;
        // Scoring the test views is not training: it/s leaves it out.
        let mut eval_seconds = 0.0;
        let mut watch = DropWatch::new(self.views);
        // Where the run starts, so the host counts rates from here, not from iteration 0.
        ctx.progress("train", u64::from(first - 1), u64::from(total));
        for it in first..=total {
            if ctx.cancelled() {
                self.save_on_interrupt(ctx)?;
                return Err(StageError::Cancelled);
            }
            // Scores at a densification (or reset) iteration are taken before it, as INRIA
            // does: just after it, fresh split children are untrained, and two test views
            // measured 5 dB lower than 250 iterations earlier (synthetic scene, 80×60).
            let before = self.trainer.restructures_at(it);
            if before {
                eval_seconds += self.maybe_eval(it, &mut last_test, ctx)?;
            }
            let stats = self.trainer.step().map_err(StageError::other)?;
            // Every step: the host decides how often to draw or print (by time, not count).
            ctx.progress("train", u64::from(it), u64::from(total));
            let clock = (start, first, eval_seconds);
            for r in stats.readings {
                last = (Some(r.loss), Some(r.psnr));
                self.report(&r, clock, &mut watch, ctx)?;
            }
            if !before {
                eval_seconds += self.maybe_eval(it, &mut last_test, ctx)?;
            }
            let due = self.checkpoint_every > 0 && it % self.checkpoint_every == 0 && it < total;
            if let Some(dir) = self.checkpoint_dir.clone().filter(|_| due) {
                self.save(&dir)?;
            }
        }
        // The last steps' readings arrive once the GPU has finished them.
        for r in self.trainer.finish().map_err(StageError::other)? {
            last = (Some(r.loss), Some(r.psnr));
            self.report(&r, (start, first, eval_seconds), &mut watch, ctx)?;
        }
        let seconds = start.elapsed().as_secs_f64();
        let outcome = Outcome {
            final_loss: last.0,
            final_psnr: last.1,
            seconds,
            it_per_s: f64::from(total - first + 1) / (seconds - eval_seconds).max(1e-9),
            last_drop: watch.last(),
            test: last_test,
        };
        let summary = json!({
            "summary": {
                "iterations": total,
                "final_loss": outcome.final_loss,
                "final_psnr": outcome.final_psnr,
                "seconds": seconds,
                "it_per_s": outcome.it_per_s,
                "last_psnr_drop": outcome.last_drop.map(|d| d.iteration),
                "test_psnr": outcome.test.as_ref().map(|t| t.psnr),
                "test_ssim": outcome.test.as_ref().and_then(|t| t.ssim),
            }
        });
        self.log.record(&summary)?;
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

    /// Training diverged (`what` says how): the output is not written, but a checkpoint and
    /// a live log kept beside it stay, and the error names them, as the checkpoint may already
    /// hold the bad values a resume would start from.
    pub fn diverged_error(&self, what: String) -> StageError {
        let mut left = Vec::new();
        if let Some(dir) = self.checkpoint_dir.as_ref().filter(|d| d.exists()) {
            let when = match self.saved_at {
                Some(i) => format!("saved at iteration {i}; it may already hold the bad values"),
                None => "the one this run started from".to_owned(),
            };
            left.push(format!("the checkpoint {} ({when})", dir.display()));
        }
        if self.log.is_live() {
            left.push(format!("the log {}", self.log.path().display()));
        }
        let left = match left.len() {
            0 => "; nothing was written".to_owned(),
            // A rerun with other rates starts afresh, which that checkpoint would refuse.
            1 => format!(
                "; the output was not written, but {} remains (remove it to start afresh)",
                left[0]
            ),
            _ => format!(
                "; the output was not written, but {} remain (remove them to start afresh)",
                left.join(" and ")
            ),
        };
        StageError::other(TrainError::Diverged(format!("{what}{left}")))
    }

    /// Replaces `dir` with the current state, atomically: an interruption while writing
    /// leaves the previous checkpoint.
    fn save(&mut self, dir: &Path) -> Result<(), StageError> {
        let state = self
            .trainer
            .snapshot(self.downscale)
            .map_err(StageError::other)?;
        let staging = Staging::beside(dir);
        state.save(staging.path()).map_err(StageError::other)?;
        staging
            .commit(dir, true)
            .map_err(|e| StageError::io(dir, e))?;
        self.saved_at = Some(self.trainer.iteration());
        Ok(())
    }

    /// The log into the output (see `TrainLog::finish`).
    pub fn finish_log(&self, output: &Path) -> Result<(), StageError> {
        self.log.finish(output)
    }

    fn save_on_interrupt(&mut self, ctx: &dyn Context) -> Result<(), StageError> {
        let Some(dir) = self.checkpoint_dir.clone() else {
            return Ok(());
        };
        if self.trainer.iteration() == 0 {
            return Ok(());
        }
        self.save(&dir)?;
        // A log inside the output goes with the discarded staging folder; a live one stays.
        let log = if self.log.is_live() {
            format!(
                ", which also continues the log {}",
                self.log.path().display()
            )
        } else {
            String::new()
        };
        ctx.warn(&format!(
            "interrupted after iteration {}; checkpoint saved to {} (continue with --resume \
             {}{log})",
            self.trainer.iteration(),
            dir.display(),
            dir.display(),
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_loss_that_is_not_a_number_stops_the_run_naming_where() {
        let reading = |iteration, loss| Reading {
            iteration,
            view: 0,
            num_gaussians: 10,
            sh_degree: 0,
            loss,
            psnr: 20.0,
        };
        assert!(diverged(&reading(7, 0.25), None).is_none());
        let e = diverged(&reading(90, f64::NAN), Some((80, 0.0123))).unwrap();
        assert_eq!(
            e,
            "the loss is NaN at iteration 90 (the last finite reading: 0.01230 at iteration 80)"
        );
        let e = diverged(&reading(10, f64::INFINITY), None).unwrap();
        assert!(
            e.contains("the loss is inf at iteration 10 (no earlier reading was finite)"),
            "{e}"
        );
    }
}
