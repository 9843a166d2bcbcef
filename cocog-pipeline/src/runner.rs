//! Running one stage into a staging path that is renamed into place on success.

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Path, PathBuf};
use std::time::{SystemTime, UNIX_EPOCH};

use serde_json::{Map, Value};

use crate::atomic::Staging;
use crate::context::Context;
use crate::options::Options;
use crate::registry::{RegistryError, StageEntry};
use crate::scene::{HistoryEntry, MANIFEST, Scene, SceneError};
use crate::stage::{OutputKind, StageError, StageRequest};

#[derive(Debug, thiserror::Error)]
pub enum RunError {
    #[error("{0}: input does not exist")]
    MissingInput(PathBuf),
    #[error("{0}: output already exists (use --force to replace it)")]
    OutputExists(PathBuf),
    #[error("{0}: names a folder, and this stage writes one file: name it, e.g. exports/scene.ply")]
    FolderForFile(PathBuf),
    #[error("{path}: --force will not replace it: {why}")]
    NotReplaceable { path: PathBuf, why: String },
    #[error("{path}: cannot write the output here: {source}")]
    Prepare {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{}", stage_failure(.stage, .source))]
    Stage {
        stage: String,
        #[source]
        source: StageError,
    },
    #[error("stage '{stage}' panicked: {message}")]
    Panicked { stage: String, message: String },
    #[error("{path}: cannot move the finished output into place: {source}")]
    Commit {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error(transparent)]
    History(#[from] SceneError),
    #[error(transparent)]
    Registry(#[from] RegistryError),
    #[error("{path}: {message}")]
    Pipeline { path: PathBuf, message: String },
}

/// "stage 'X' failed: …", unless the stage's message already names the stage (option errors
/// do), where the prefix would only repeat it.
fn stage_failure(stage: &str, source: &StageError) -> String {
    let message = source.to_string();
    if message.starts_with(&format!("stage '{stage}'")) {
        message
    } else {
        format!("stage '{stage}' failed: {message}")
    }
}

impl RunError {
    pub fn is_cancelled(&self) -> bool {
        matches!(
            self,
            Self::Stage {
                source: StageError::Cancelled,
                ..
            }
        )
    }
}

/// Runs one stage from `input` to `output`, all or nothing.
///
/// Options are checked against the stage's schema first; the stage writes into a hidden
/// sibling of `output` which is renamed into place only on success. Scene outputs get a
/// history entry naming the stage, its provider and its options.
pub fn run_stage(
    entry: &StageEntry,
    input: &Path,
    output: &Path,
    given: &Map<String, Value>,
    force: bool,
    ctx: &dyn Context,
) -> Result<Value, RunError> {
    let how = RunHow {
        force,
        ..RunHow::default()
    };
    run_stage_with(entry, input, output, given, &how, ctx)
}

/// How the runner treats a stage's output, beyond the stage's own options.
#[derive(Clone, Copy, Debug, Default)]
pub struct RunHow {
    /// Replace an existing output.
    pub force: bool,
    /// Copy (or hard-link) the photos into a scene output, so it is self-contained.
    pub copy_images: bool,
}

/// [`run_stage`] with every runner setting.
pub fn run_stage_with(
    entry: &StageEntry,
    input: &Path,
    output: &Path,
    given: &Map<String, Value>,
    how: &RunHow,
    ctx: &dyn Context,
) -> Result<Value, RunError> {
    let force = how.force;
    let name = entry.info.name.clone();
    let stage_err = |source| RunError::Stage {
        stage: name.clone(),
        source,
    };
    if !input.exists() {
        return Err(RunError::MissingInput(input.to_path_buf()));
    }
    if (output.exists() || output.is_symlink()) && !force {
        return Err(RunError::OutputExists(output.to_path_buf()));
    }
    if let Some(why) = crate::replace::refusal(output, input, entry.info.output) {
        return Err(RunError::NotReplaceable {
            path: output.to_path_buf(),
            why,
        });
    }
    if entry.info.output == OutputKind::File && ends_with_separator(output) {
        return Err(RunError::FolderForFile(output.to_path_buf()));
    }
    let options = Options::validate(&name, &entry.info.options, given).map_err(stage_err)?;
    let parent = output
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or_else(|| Path::new("."));
    std::fs::create_dir_all(parent).map_err(|source| RunError::Prepare {
        path: parent.to_path_buf(),
        source,
    })?;
    crate::atomic::remove_stale_temps(output);
    let staging = Staging::beside(output);
    // Errors name the folder the user chose, not the hidden staging path inside it.
    let unwritable = |source| RunError::Prepare {
        path: parent.to_path_buf(),
        source,
    };
    match entry.info.output {
        OutputKind::Dir => std::fs::create_dir(staging.path()).map_err(unwritable)?,
        OutputKind::File => {
            std::fs::write(staging.path(), b"").map_err(unwritable)?;
            let _ = std::fs::remove_file(staging.path());
        }
    }
    let req = StageRequest {
        input: input.to_path_buf(),
        output: staging.path().to_path_buf(),
        options,
    };
    let summary = match catch_unwind(AssertUnwindSafe(|| entry.stage.run(&req, ctx))) {
        Ok(r) => r.map_err(stage_err)?,
        Err(p) => {
            let message = p
                .downcast_ref::<&str>()
                .map(|s| (*s).to_owned())
                .or_else(|| p.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "unknown panic".to_owned());
            return Err(RunError::Panicked {
                stage: name,
                message,
            });
        }
    };
    if entry.info.output == OutputKind::Dir && staging.path().is_dir() {
        let marker = staging.path().join(crate::replace::MARKER);
        std::fs::write(&marker, b"").map_err(|source| RunError::Prepare {
            path: output.to_path_buf(),
            source,
        })?;
    }
    if entry.info.output == OutputKind::Dir && staging.path().join(MANIFEST).exists() {
        crate::travel::take_along(staging.path(), how.copy_images)?;
        record_history(
            staging.path(),
            entry,
            input,
            &req.options,
            summary.get("resolved"),
        )?;
    }
    staging
        .commit(output, force)
        .map_err(|source| RunError::Commit {
            path: output.to_path_buf(),
            source,
        })?;
    remove_superseded_checkpoint(&req.options, &summary, ctx);
    Ok(summary)
}

/// A stage that kept in-progress files beside its output (its `checkpoint_dir` and
/// `live_log` options: a checkpoint, the log the user follows) says when its committed output
/// supersedes them; only then, and only those, are removed. Until then they are what lets an
/// interrupted run continue, log included.
fn remove_superseded_checkpoint(options: &Options, summary: &Value, ctx: &dyn Context) {
    let done = summary
        .get("checkpoint_superseded")
        .and_then(Value::as_bool)
        == Some(true);
    if !done {
        return;
    }
    let dir = options.get_path("checkpoint_dir").filter(|d| d.is_dir());
    let log = options.get_path("live_log").filter(|f| f.is_file());
    let removed = [
        dir.map(|d| (std::fs::remove_dir_all(&d), d, "checkpoint")),
        log.map(|f| (std::fs::remove_file(&f), f, "log")),
    ];
    for (result, path, what) in removed.into_iter().flatten() {
        if let Err(e) = result {
            ctx.warn(&format!(
                "{}: could not remove the finished run's {what}: {e}",
                path.display()
            ));
        }
    }
}

fn ends_with_separator(p: &Path) -> bool {
    p.as_os_str()
        .to_string_lossy()
        .ends_with(std::path::is_separator)
}

fn record_history(
    dir: &Path,
    entry: &StageEntry,
    input: &Path,
    options: &Options,
    resolved: Option<&Value>,
) -> Result<(), SceneError> {
    let mut scene = Scene::load(dir)?;
    let finished_at = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    scene.history.push(HistoryEntry {
        stage: entry.info.name.clone(),
        provider: entry.provider.to_string(),
        input: input.display().to_string(),
        options: serde_json::to_value(options).unwrap_or(Value::Null),
        resolved: resolved.cloned(),
        cocog_version: crate::VERSION.to_owned(),
        finished_at,
    });
    scene.save(dir)
}

#[cfg(test)]
mod stage_failure_tests {
    use super::{RunError, StageError};

    fn shown(stage: &str, source: StageError) -> String {
        RunError::Stage {
            stage: stage.into(),
            source,
        }
        .to_string()
    }

    #[test]
    fn a_message_that_names_its_stage_is_not_prefixed_again() {
        let options = "stage 'ingest-photos' option 'focal-factor': expected a number, got 0";
        assert_eq!(
            shown("ingest-photos", StageError::Options(options.into())),
            options
        );
        assert_eq!(
            shown(
                "ingest-photos",
                StageError::Input("photos/: found 0 photos".into())
            ),
            "stage 'ingest-photos' failed: photos/: found 0 photos"
        );
        // Another stage's name at the start is not this stage's: keep the prefix.
        let other = shown(
            "train",
            StageError::Options("stage 'trainer' option 'x': bad".into()),
        );
        assert!(other.starts_with("stage 'train' failed: "));
    }
}
