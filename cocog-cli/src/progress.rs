//! The terminal side of a running stage: indicatif bars, log lines and Ctrl-C.

use std::collections::HashMap;
use std::io::IsTerminal;
use std::sync::Arc;
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use cocog_pipeline::{Context, LogLevel};
use indicatif::{MultiProgress, ProgressBar, ProgressDrawTarget, ProgressStyle};

pub struct CliContext {
    bars: MultiProgress,
    tasks: Mutex<HashMap<String, Task>>,
    level: LogLevel,
    show_bars: bool,
    cancel: Arc<AtomicBool>,
}

struct Task {
    bar: ProgressBar,
    started: Instant,
}

impl CliContext {
    pub fn new(level: LogLevel, cancel: Arc<AtomicBool>) -> Self {
        // Bars only make sense on a terminal; in CI and pipes they would be noise.
        let show_bars = level >= LogLevel::Info && std::io::stderr().is_terminal();
        let target = if show_bars {
            ProgressDrawTarget::stderr()
        } else {
            ProgressDrawTarget::hidden()
        };
        Self {
            bars: MultiProgress::with_draw_target(target),
            tasks: Mutex::new(HashMap::new()),
            level,
            show_bars,
            cancel,
        }
    }

    fn new_bar(&self, task: &str, total: u64) -> ProgressBar {
        let bar = if total == 0 {
            ProgressBar::new_spinner().with_style(
                ProgressStyle::with_template("{spinner} {msg} {pos} ({per_sec}, {elapsed})")
                    .unwrap_or_else(|_| ProgressStyle::default_spinner()),
            )
        } else {
            ProgressBar::new(total).with_style(
                ProgressStyle::with_template(
                    "{msg:>12} [{bar:30}] {pos}/{len} {per_sec} ETA {eta} ({elapsed})",
                )
                .unwrap_or_else(|_| ProgressStyle::default_bar())
                .progress_chars("=> "),
            )
        };
        let bar = self.bars.add(bar);
        bar.set_message(task.to_owned());
        bar.enable_steady_tick(Duration::from_millis(200));
        bar
    }
}

impl Context for CliContext {
    fn log(&self, level: LogLevel, message: &str) {
        if level > self.level {
            return;
        }
        let line = match level {
            LogLevel::Info => message.to_owned(),
            _ => format!("{}: {message}", level.as_str()),
        };
        if self.show_bars {
            let _ = self.bars.println(line);
        } else {
            eprintln!("{line}");
        }
    }

    fn progress(&self, task: &str, done: u64, total: u64) {
        let Ok(mut tasks) = self.tasks.lock() else {
            return;
        };
        let t = tasks.entry(task.to_owned()).or_insert_with(|| Task {
            bar: self.new_bar(task, total),
            started: Instant::now(),
        });
        if total > 0 && t.bar.length() != Some(total) {
            t.bar.set_length(total);
        }
        t.bar.set_position(done);
        if total > 0 && done >= total {
            t.bar.finish_and_clear();
            let secs = t.started.elapsed().as_secs_f64();
            let rate = if secs > 0.0 { done as f64 / secs } else { 0.0 };
            tasks.remove(task);
            self.log(
                LogLevel::Info,
                &format!("{task}: {done}/{total} in {secs:.1} s ({rate:.1}/s)"),
            );
        }
    }

    fn cancelled(&self) -> bool {
        self.cancel.load(Ordering::Relaxed)
    }
}
