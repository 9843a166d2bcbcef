//! Runs the COLMAP command-line program: finds it, learns which options this build accepts,
//! and runs one command at a time with its output appended to a log file and its progress
//! lines relayed to the stage's progress bar.

use std::collections::HashMap;
use std::fs::File;
use std::io::{BufRead, BufReader, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use cocog_pipeline::{Context, StageError};

/// How to install COLMAP, for the error when it is missing.
const INSTALL: &str = "install COLMAP (Debian/Ubuntu: `apt install colmap`; macOS: \
    `brew install colmap`; conda: `conda install -c conda-forge colmap`; Windows: a release \
    from https://github.com/colmap/colmap/releases) or pass --colmap PATH";

/// One COLMAP executable and the options each of its commands accepts.
pub(crate) struct Colmap {
    exe: PathBuf,
    /// First line of `colmap -h`, e.g. "COLMAP 3.8 -- Structure-from-Motion and Multi-View Stereo".
    pub version: String,
    log: PathBuf,
    /// Option names per command, read from `colmap COMMAND -h` on first use.
    options: Mutex<HashMap<String, Vec<String>>>,
}

/// A command's arguments: `--Section.name value` pairs, some of them optional tuning that a
/// build without the option simply does not get.
pub(crate) struct Args {
    command: &'static str,
    required: Vec<(String, String)>,
    tuning: Vec<(String, String)>,
    /// The progress total where COLMAP's lines do not say it (mapping).
    total: u64,
}

impl Args {
    pub fn new(command: &'static str) -> Self {
        Self {
            command,
            required: Vec::new(),
            tuning: Vec::new(),
            total: 0,
        }
    }

    /// The progress total for lines that carry only a count.
    pub fn total(mut self, total: usize) -> Self {
        self.total = total as u64;
        self
    }

    /// An option the command cannot run correctly without.
    pub fn arg(mut self, name: &str, value: impl ToString) -> Self {
        self.required.push((name.to_owned(), value.to_string()));
        self
    }

    /// A setting worth passing where this COLMAP has it (names change between releases).
    pub fn tune(mut self, name: &str, value: impl ToString) -> Self {
        self.tuning.push((name.to_owned(), value.to_string()));
        self
    }
}

impl Colmap {
    /// `explicit` (the user's --colmap), else `colmap` on PATH. `log` receives every command's
    /// output.
    pub fn find(explicit: Option<&Path>, log: PathBuf) -> Result<Self, StageError> {
        let exe = explicit.map_or_else(|| PathBuf::from("colmap"), Path::to_path_buf);
        let out = Command::new(&exe).arg("-h").output().map_err(|e| {
            let what = match explicit {
                Some(p) => format!("COLMAP at {} could not be run ({e})", p.display()),
                None => format!("COLMAP was not found on PATH ({e})"),
            };
            StageError::Input(format!("{what}; {INSTALL}"))
        })?;
        let text = String::from_utf8_lossy(&out.stdout);
        let version = text
            .lines()
            .find(|l| l.starts_with("COLMAP"))
            .ok_or_else(|| {
                StageError::Input(format!(
                    "{} -h did not print COLMAP's banner: is it COLMAP? {INSTALL}",
                    exe.display()
                ))
            })?
            .trim()
            .to_owned();
        Ok(Self {
            exe,
            version,
            log,
            options: Mutex::new(HashMap::new()),
        })
    }

    fn accepts(&self, command: &str, option: &str) -> Result<bool, StageError> {
        let mut cache = self.options.lock().unwrap_or_else(|p| p.into_inner());
        if !cache.contains_key(command) {
            let out = Command::new(&self.exe)
                .args([command, "-h"])
                .output()
                .map_err(|e| failed(format!("{} {command} -h: {e}", self.exe.display())))?;
            let names = String::from_utf8_lossy(&out.stdout)
                .split_whitespace()
                .filter_map(|w| w.strip_prefix("--"))
                .map(str::to_owned)
                .collect();
            cache.insert(command.to_owned(), names);
        }
        Ok(cache[command].iter().any(|o| o == option))
    }

    /// Runs one command to completion. Tuning options this build lacks are skipped with a
    /// debug line; a missing required option is an error naming the version.
    pub fn run(&self, args: Args, task: &str, ctx: &dyn Context) -> Result<(), StageError> {
        let mut cmd = Command::new(&self.exe);
        cmd.arg(args.command);
        for (name, value) in &args.required {
            if !self.accepts(args.command, name)? {
                return Err(StageError::Input(format!(
                    "{} does not accept --{name} for `{}`; cocog is tested with COLMAP 3.8",
                    self.version, args.command
                )));
            }
            cmd.arg(format!("--{name}")).arg(value);
        }
        for (name, value) in &args.tuning {
            if self.accepts(args.command, name)? {
                cmd.arg(format!("--{name}")).arg(value);
            } else {
                ctx.debug(&format!(
                    "{} has no --{name}; left at its default",
                    self.version
                ));
            }
        }
        // Otherwise glog also writes a log file per command into $TMPDIR (or /tmp) that nothing
        // removes: hundreds after a few ingests. On stderr its lines land in our log instead.
        if self.accepts(args.command, "log_to_stderr")? {
            cmd.arg("--log_to_stderr").arg("1");
        }
        let mut log = File::options()
            .create(true)
            .append(true)
            .open(&self.log)
            .map_err(|e| StageError::io(&self.log, e))?;
        writeln!(log, "\n$ {cmd:?}").map_err(|e| StageError::io(&self.log, e))?;
        let child = cmd
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .map_err(|e| failed(format!("{}: {e}", self.exe.display())))?;
        let status = self.watch(child, log, task, args.total, ctx)?;
        if status.success() {
            return Ok(());
        }
        Err(failed(format!(
            "COLMAP {} failed ({status}); its last lines:\n{}\nfull log: {}",
            args.command,
            tail(&self.log, 8),
            self.log.display()
        )))
    }

    /// Copies the child's output into the log, relays progress, and kills it on cancel.
    fn watch(
        &self,
        mut child: Child,
        log: File,
        task: &str,
        total_hint: u64,
        ctx: &dyn Context,
    ) -> Result<std::process::ExitStatus, StageError> {
        let log = Arc::new(Mutex::new(log));
        let last = Arc::new(Mutex::new(None::<(u64, u64)>));
        let mut readers = Vec::new();
        let streams: [Box<dyn std::io::Read + Send>; 2] = [
            Box::new(child.stdout.take().expect("piped")),
            Box::new(child.stderr.take().expect("piped")),
        ];
        for stream in streams {
            let (log, last) = (Arc::clone(&log), Arc::clone(&last));
            readers.push(std::thread::spawn(move || {
                for line in BufReader::new(stream).lines().map_while(Result::ok) {
                    if let Some(p) = progress_of(&line) {
                        *last.lock().unwrap_or_else(|p| p.into_inner()) = Some(p);
                    }
                    let mut f = log.lock().unwrap_or_else(|p| p.into_inner());
                    // A full disk shows up when the scene is written; the log is best effort.
                    let _ = writeln!(f, "{line}");
                }
            }));
        }
        // Report changes only, and hold the bar just short of done until the command has
        // exited: the mapper's count can reach the total and then retry images.
        let mut shown = None;
        let status = loop {
            let last = *last.lock().unwrap_or_else(|p| p.into_inner());
            if let Some((done, total)) = last {
                let total = if total == 0 { total_hint } else { total };
                let now = (done.min(total.saturating_sub(1)), total);
                if shown != Some(now) {
                    ctx.progress(task, now.0, now.1);
                    shown = Some(now);
                }
            }
            if ctx.cancelled() {
                let _ = child.kill();
                let _ = child.wait();
                return Err(StageError::Cancelled);
            }
            match child.try_wait() {
                Ok(Some(status)) => break status,
                Ok(None) => std::thread::sleep(Duration::from_millis(100)),
                Err(e) => return Err(failed(format!("waiting for COLMAP: {e}"))),
            }
        };
        if let (true, Some((_, total))) = (status.success(), shown) {
            ctx.progress(task, total, total);
        }
        for r in readers {
            let _ = r.join();
        }
        Ok(status)
    }
}

/// COLMAP's progress lines: "Processed file [3/24]" (extraction), "Matching block [1/2, 2/2]"
/// (exhaustive), "Matching image [5/24]" (sequential, vocabulary tree), "Registering image #7
/// (3)" (mapping; the count is the registered images so far plus one, out of an unknown total,
/// so its total comes from the caller), "Undistorting image [2/24]".
fn progress_of(line: &str) -> Option<(u64, u64)> {
    let line = line.trim();
    let bracket = |s: &str| -> Option<(u64, u64)> {
        let inner = s.split('[').nth(1)?.split(']').next()?;
        let (a, b) = inner.split_once('/')?;
        Some((a.trim().parse().ok()?, b.trim().parse().ok()?))
    };
    if line.starts_with("Matching block [") {
        // "[i/B, j/B]": block (i, j) of a B×B grid.
        let inner = line.split('[').nth(1)?.split(']').next()?;
        let (first, second) = inner.split_once(',')?;
        let (i, b) = first.split_once('/')?;
        let (j, _) = second.split_once('/')?;
        let (i, b, j): (u64, u64, u64) = (
            i.trim().parse().ok()?,
            b.trim().parse().ok()?,
            j.trim().parse().ok()?,
        );
        return Some(((i - 1).saturating_mul(b) + j, b * b));
    }
    if [
        "Processed file [",
        "Matching image [",
        "Undistorting image [",
    ]
    .iter()
    .any(|p| line.starts_with(p))
    {
        return bracket(line);
    }
    if let Some(rest) = line.strip_prefix("Registering image #") {
        let count = rest
            .split('(')
            .nth(1)?
            .split(')')
            .next()?
            .trim()
            .parse()
            .ok()?;
        return Some((count, 0));
    }
    None
}

/// COLMAP failing to run or finish: neither the user's input nor an option.
fn failed(message: String) -> StageError {
    StageError::Other(message.into())
}

/// The last `n` lines of a text file, for error messages.
pub(crate) fn tail(path: &Path, n: usize) -> String {
    let text = std::fs::read_to_string(path).unwrap_or_default();
    let lines: Vec<&str> = text.lines().filter(|l| !l.trim().is_empty()).collect();
    lines[lines.len().saturating_sub(n)..].join("\n")
}

#[cfg(test)]
mod tests {
    use super::progress_of;

    #[test]
    fn reads_colmap_3_8_progress_lines() {
        assert_eq!(progress_of("Processed file [3/24]"), Some((3, 24)));
        assert_eq!(
            progress_of("Matching block [2/3, 1/3] in 0.5s"),
            Some((4, 9))
        );
        assert_eq!(progress_of("Matching image [5/24] in 0.1s"), Some((5, 24)));
        assert_eq!(progress_of("Registering image #17 (3)"), Some((3, 0)));
        assert_eq!(progress_of("Undistorting image [2/24]"), Some((2, 24)));
        assert_eq!(progress_of("  Features:        1117"), None);
    }
}
