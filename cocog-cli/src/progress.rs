//! The terminal side of a running stage: indicatif bars, log lines and Ctrl-C.
//!
//! Without a terminal (a log file, CI, `nohup`), bars would be noise, and a stage's own log
//! lines may come only every tenth of the run: hours apart on a slow machine. There a running
//! task prints a progress line at a steady interval instead (`--progress-every`).

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
    /// Interval of the progress lines printed instead of bars; `None`: none.
    line_every: Option<Duration>,
    cancel: Arc<AtomicBool>,
}

struct Task {
    bar: ProgressBar,
    started: Instant,
    last_line: Instant,
    /// Count at the first report: a resumed run starts mid-way, and rates must count only the
    /// work done since.
    first: u64,
    /// Count at the last progress line, and the rate the lines report (`recent_rate`).
    last_done: u64,
    rate: Option<f64>,
}

impl CliContext {
    /// `line_every`: seconds between progress lines when stderr is not a terminal; 0: none.
    pub fn new(level: LogLevel, cancel: Arc<AtomicBool>, line_every: f64) -> Self {
        // Bars only make sense on a terminal; in CI and pipes they would be noise.
        let show_bars = level >= LogLevel::Info && std::io::stderr().is_terminal();
        // A duration too long to represent is as good as never.
        let line_every = (level >= LogLevel::Info && !show_bars && line_every > 0.0)
            .then(|| Duration::try_from_secs_f64(line_every).ok())
            .flatten();
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
            line_every,
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
        let t = tasks.entry(task.to_owned()).or_insert_with(|| {
            let bar = self.new_bar(task, total);
            bar.set_position(done);
            // The bar's rate estimate must not read the resumed start as work just done.
            bar.reset_eta();
            Task {
                bar,
                started: Instant::now(),
                last_line: Instant::now(),
                first: done,
                last_done: done,
                rate: None,
            }
        });
        if total > 0 && t.bar.length() != Some(total) {
            t.bar.set_length(total);
        }
        t.bar.set_position(done);
        if total > 0 && done >= total {
            t.bar.finish_and_clear();
            let line = finished_line(task, done, total, t.first, t.started.elapsed());
            tasks.remove(task);
            self.log(LogLevel::Info, &line);
        } else if let Some(every) = self.line_every
            && t.last_line.elapsed() >= every
        {
            let since_last = t.last_line.elapsed().as_secs_f64();
            let elapsed = t.started.elapsed();
            let overall = rate(done, t.first, elapsed.as_secs_f64());
            let interval = rate(done, t.last_done, since_last);
            let r = recent_rate(t.rate, overall, interval);
            t.rate = Some(r);
            t.last_line = Instant::now();
            t.last_done = done;
            let line = progress_line(task, done, total, r, elapsed);
            eprintln!("{line}");
        }
    }

    fn cancelled(&self) -> bool {
        self.cancel.load(Ordering::Relaxed)
    }
}

/// Items per second since the task's first report at count `first`.
fn rate(done: u64, first: u64, secs: f64) -> f64 {
    if secs > 0.0 {
        done.saturating_sub(first) as f64 / secs
    } else {
        0.0
    }
}

/// The rate a progress line reports: at the first line the average since the start, then a
/// moving average of each interval's rate (weight 0.3 on the newest, about the last three lines).
/// Training slows as it goes (the blur model starts, the Gaussians multiply), so the average
/// since the start would promise an end several times too early.
fn recent_rate(previous: Option<f64>, overall: f64, interval: f64) -> f64 {
    match previous {
        None => overall,
        Some(p) => 0.3 * interval + 0.7 * p,
    }
}

/// `train: 7000/7000 in 123.0 s (9.8/s)`; a resumed task says where it resumed.
fn finished_line(task: &str, done: u64, total: u64, first: u64, elapsed: Duration) -> String {
    let secs = elapsed.as_secs_f64();
    let rate = rate(done, first, secs);
    let resumed = if first > 0 {
        format!(", resumed at {first}")
    } else {
        String::new()
    };
    format!(
        "{task}: {done}/{total} in {secs:.1} s ({}{resumed})",
        speed(rate)
    )
}

/// Items per second, or seconds per item when under one a second (a 24-Mpixel photo's step on
/// a CPU adapter), so slow work does not read `0.0/s`.
fn speed(rate: f64) -> String {
    if rate > 0.0 && rate < 1.0 {
        format!("{:.1} s each", 1.0 / rate)
    } else {
        format!("{rate:.1}/s")
    }
}

/// `train: 1200/7000 (17%), 9.8/s, 2m 03s elapsed, about 9m 55s left`; without a total, the
/// count and rate only. The time left is at `rate` (`recent_rate`).
fn progress_line(task: &str, done: u64, total: u64, rate: f64, elapsed: Duration) -> String {
    let secs = elapsed.as_secs_f64();
    let mut line = format!("{task}: {done}");
    if total > 0 {
        let percent = 100.0 * done as f64 / total as f64;
        line.push_str(&format!("/{total} ({percent:.0}%)"));
    }
    line.push_str(&format!(", {}, {} elapsed", speed(rate), clock(secs)));
    if total > done && rate > 0.0 {
        let left = (total - done) as f64 / rate;
        line.push_str(&format!(", about {} left", clock(left)));
    }
    line
}

fn clock(secs: f64) -> String {
    let s = secs.round() as u64;
    match (s / 3600, s / 60 % 60, s % 60) {
        (0, 0, s) => format!("{s}s"),
        (0, m, s) => format!("{m}m {s:02}s"),
        (h, m, _) => format!("{h}h {m:02}m"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The first line's rate: the average since the task's first report.
    fn first_line(task: &str, done: u64, total: u64, first: u64, elapsed: Duration) -> String {
        let r = recent_rate(None, rate(done, first, elapsed.as_secs_f64()), 0.0);
        progress_line(task, done, total, r, elapsed)
    }

    #[test]
    fn progress_lines_give_count_rate_and_time_left() {
        let line = first_line("train", 1200, 7000, 0, Duration::from_secs(123));
        assert_eq!(
            line,
            "train: 1200/7000 (17%), 9.8/s, 2m 03s elapsed, about 9m 55s left"
        );
        let line = first_line("load", 5, 0, 0, Duration::from_secs(4000));
        assert_eq!(line, "load: 5, 800.0 s each, 1h 06m elapsed");
        let line = first_line("train", 0, 6, 0, Duration::from_secs(3));
        assert_eq!(line, "train: 0/6 (0%), 0.0/s, 3s elapsed");
    }

    /// A run that slows from 10/s to 1/s (lines every 10 s): within a few lines the time left
    /// follows the new pace, where the average since the start (here 7.6/s after 50 s at 10/s
    /// and 30 s at 1/s) would promise the end about 8× too early.
    #[test]
    fn time_left_follows_a_run_that_slows_down() {
        let mut r = recent_rate(None, 10.0, 0.0);
        for _ in 0..4 {
            r = recent_rate(Some(r), 10.0, 10.0);
        }
        assert_eq!(r, 10.0);
        for _ in 0..3 {
            r = recent_rate(Some(r), 7.6, 1.0);
        }
        // 1 + 9 · 0.7³
        assert!((r - 4.087).abs() < 1e-9, "{r}");
        for _ in 0..7 {
            r = recent_rate(Some(r), 7.6, 1.0);
        }
        // 1 + 9 · 0.7¹⁰
        assert!((r - 1.2542).abs() < 1e-4, "{r}");
        let line = progress_line("train", 1000, 2000, r, Duration::from_secs(150));
        assert!(
            line.ends_with("1.3/s, 2m 30s elapsed, about 13m 17s left"),
            "{line}"
        );
    }

    #[test]
    fn slow_work_reads_in_seconds_each() {
        let line = first_line("train", 2, 6, 0, Duration::from_secs(86));
        assert_eq!(
            line,
            "train: 2/6 (33%), 43.0 s each, 1m 26s elapsed, about 2m 52s left"
        );
        let line = finished_line("train", 6, 6, 0, Duration::from_millis(249_700));
        assert_eq!(line, "train: 6/6 in 249.7 s (41.6 s each)");
    }

    #[test]
    fn a_resumed_task_counts_its_rate_from_where_it_resumed() {
        let line = first_line("train", 6000, 7000, 5000, Duration::from_secs(100));
        assert_eq!(
            line,
            "train: 6000/7000 (86%), 10.0/s, 1m 40s elapsed, about 1m 40s left"
        );
        let line = finished_line("train", 2641, 2641, 2640, Duration::from_millis(500));
        assert_eq!(line, "train: 2641/2641 in 0.5 s (2.0/s, resumed at 2640)");
        let line = finished_line("train", 300, 300, 0, Duration::from_secs(30));
        assert_eq!(line, "train: 300/300 in 30.0 s (10.0/s)");
    }
}
