//! `train-log.jsonl`, written where the user can `tail -f` it while the run goes on.
//!
//! The stage's output folder is a hidden staging path until the run succeeds, so a log kept
//! there cannot be found while it matters. With the `live_log` option (the CLI passes
//! `OUTPUT.train-log.jsonl`, `cocog run` the same beside each stage's output) the log lives
//! beside the output, next to the checkpoint it belongs with: a run stopped by Ctrl-C or
//! SIGKILL leaves both, `--resume` continues both, and a successful run copies the log into
//! its output, after which the runner removes the live one.

use std::fs::{File, OpenOptions};
use std::io::{BufRead, BufReader, Read, Write};
use std::path::{Path, PathBuf};

use cocog_pipeline::StageError;
use serde_json::Value;

/// The log's name inside a train output.
pub const LOG_FILE: &str = "train-log.jsonl";

pub(super) struct TrainLog {
    path: PathBuf,
    file: File,
    /// Kept beside the output (copied in by `finish`) rather than written inside it.
    live: bool,
}

impl TrainLog {
    /// The log for a run writing `output`: `live_log` when given, else `output`'s own. A
    /// resumed run keeps the log of the run it continues: it appends to it when that is this
    /// very file (an interrupted run of the same output), and copies it first otherwise.
    pub fn open(
        live_log: Option<&Path>,
        resume: Option<&Path>,
        output: &Path,
    ) -> Result<Self, StageError> {
        let path = live_log.map_or_else(|| output.join(LOG_FILE), Path::to_path_buf);
        let io = |e| StageError::io(&path, e);
        let earlier = resume.and_then(earlier_log);
        let continuing = earlier.as_deref().is_some_and(|e| same_file(e, &path));
        if !continuing {
            refuse_foreign(&path)?;
        }
        let mut file = OpenOptions::new()
            .create(true)
            .write(true)
            .append(continuing)
            .truncate(!continuing)
            .open(&path)
            .map_err(io)?;
        if let Some(e) = earlier.filter(|_| !continuing) {
            let mut from = File::open(&e).map_err(|err| StageError::io(&e, err))?;
            std::io::copy(&mut from, &mut file).map_err(io)?;
        }
        end_partial_line(&path, &mut file).map_err(io)?;
        Ok(Self {
            live: live_log.is_some(),
            path,
            file,
        })
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Kept beside the output, so it outlives a failed or interrupted run.
    pub fn is_live(&self) -> bool {
        self.live
    }

    /// One JSON record on its own line, flushed at once: `tail -f` shows it, and a killed
    /// run's log still says how far it got.
    pub fn record(&mut self, value: &Value) -> Result<(), StageError> {
        // `File` is unbuffered: the line reaches the OS in one write.
        self.file
            .write_all(format!("{value}\n").as_bytes())
            .map_err(|e| StageError::io(&self.path, e))
    }

    /// Puts the finished log into the output. A copy, not a move: if the runner cannot
    /// commit the output, the live log stays with the checkpoint a rerun resumes from.
    pub fn finish(&self, output: &Path) -> Result<(), StageError> {
        if self.live {
            let dst = output.join(LOG_FILE);
            std::fs::copy(&self.path, &dst).map_err(|e| StageError::io(&dst, e))?;
        }
        Ok(())
    }
}

/// The log that goes with a checkpoint at `resume`, in the layouts cocog writes: a train
/// output's `train-log.jsonl` beside its `checkpoint/`, or `X.train-log.jsonl` beside an
/// in-progress `X.checkpoint/`.
fn earlier_log(resume: &Path) -> Option<PathBuf> {
    let dir = if resume.is_file() {
        resume.parent()?
    } else {
        resume
    };
    let candidate = if dir.join("checkpoint").is_dir() {
        dir.join(LOG_FILE)
    } else if dir.file_name()? == "checkpoint" {
        dir.parent()?.join(LOG_FILE)
    } else {
        let name = dir.file_name()?.to_str()?.strip_suffix(".checkpoint")?;
        dir.with_file_name(format!("{name}.{LOG_FILE}"))
    };
    candidate.is_file().then_some(candidate)
}

fn same_file(a: &Path, b: &Path) -> bool {
    match (a.canonicalize(), b.canonicalize()) {
        (Ok(a), Ok(b)) => a == b,
        _ => false,
    }
}

/// A fresh run replaces a stale log of an earlier run of its output, but nothing else of the
/// same name: a file whose first line is not a JSON object is not cocog's.
fn refuse_foreign(path: &Path) -> Result<(), StageError> {
    let Ok(file) = File::open(path) else {
        return Ok(());
    };
    let mut first = String::new();
    BufReader::new(file.take(1 << 16))
        .read_line(&mut first)
        .map_err(|e| StageError::io(path, e))?;
    let ours = first.trim().is_empty()
        || serde_json::from_str::<Value>(first.trim()).is_ok_and(|v| v.is_object());
    if ours {
        return Ok(());
    }
    Err(StageError::Input(format!(
        "{}: exists and is not a cocog training log; remove it or choose another output",
        path.display()
    )))
}

/// A run killed mid-line leaves a line without its end; the next record starts on its own.
fn end_partial_line(path: &Path, file: &mut File) -> std::io::Result<()> {
    let text = std::fs::read(path)?;
    if text.last().is_some_and(|&b| b != b'\n') {
        file.write_all(b"\n")?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lines(p: &Path) -> Vec<String> {
        std::fs::read_to_string(p)
            .unwrap()
            .lines()
            .map(str::to_owned)
            .collect()
    }

    #[test]
    fn a_resumed_run_keeps_the_log_it_continues() {
        let tmp = tempfile::tempdir().unwrap();
        let t = tmp.path();
        let (out, live, ckpt) = (
            t.join("out"),
            t.join("o.train-log.jsonl"),
            t.join("o.checkpoint"),
        );
        std::fs::create_dir_all(&out).unwrap();
        std::fs::create_dir_all(&ckpt).unwrap();
        // An interrupted run: its log ends mid-line.
        std::fs::write(&live, "{\"iteration\": 10}\n{\"iter").unwrap();
        let mut log = TrainLog::open(Some(&live), Some(&ckpt), &out).unwrap();
        log.record(&serde_json::json!({"iteration": 11})).unwrap();
        log.finish(&out).unwrap();
        let want = ["{\"iteration\": 10}", "{\"iter", "{\"iteration\":11}"];
        assert_eq!(lines(&live), want);
        assert_eq!(lines(&out.join(LOG_FILE)), want);

        // Resuming a finished output elsewhere copies its log into the new one.
        let (out2, live2) = (t.join("out2"), t.join("o2.train-log.jsonl"));
        std::fs::create_dir_all(out.join("checkpoint")).unwrap();
        std::fs::create_dir_all(&out2).unwrap();
        let mut log = TrainLog::open(Some(&live2), Some(&out), &out2).unwrap();
        log.record(&serde_json::json!({"iteration": 12})).unwrap();
        assert_eq!(lines(&live2)[..3], want);
        assert_eq!(lines(&live2)[3], "{\"iteration\":12}");
        assert_eq!(
            earlier_log(&out.join("checkpoint")),
            Some(out.join(LOG_FILE))
        );
    }

    #[test]
    fn a_fresh_run_replaces_only_a_stale_log() {
        let tmp = tempfile::tempdir().unwrap();
        let (out, live) = (tmp.path().join("out"), tmp.path().join("o.train-log.jsonl"));
        std::fs::create_dir_all(&out).unwrap();
        std::fs::write(&live, "{\"iteration\": 10}\n").unwrap();
        let mut log = TrainLog::open(Some(&live), None, &out).unwrap();
        log.record(&serde_json::json!({"start": {}})).unwrap();
        assert_eq!(lines(&live), ["{\"start\":{}}"]);
        std::fs::write(&live, "my notes\n").unwrap();
        let err = TrainLog::open(Some(&live), None, &out).err().unwrap();
        assert!(
            err.to_string().contains("not a cocog training log"),
            "{err}"
        );
        assert_eq!(lines(&live), ["my notes"]);
    }
}
