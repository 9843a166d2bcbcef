//! Running stages: one into a staging path that is renamed into place on success, or a
//! chain from a `pipeline.toml`.

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Path, PathBuf};
use std::time::{SystemTime, UNIX_EPOCH};

use serde::Deserialize;
use serde_json::{Map, Value, json};

use crate::atomic::Staging;
use crate::context::Context;
use crate::options::Options;
use crate::registry::{Registry, RegistryError, StageEntry};
use crate::scene::{HistoryEntry, MANIFEST, Scene, SceneError};
use crate::stage::{OutputKind, StageError, StageKind, StageRequest};

#[derive(Debug, thiserror::Error)]
pub enum RunError {
    #[error("{0}: input does not exist")]
    MissingInput(PathBuf),
    #[error("{0}: output already exists (use --force to replace it)")]
    OutputExists(PathBuf),
    #[error("{path}: --force will not replace it: {why}")]
    NotReplaceable { path: PathBuf, why: String },
    #[error("{path}: cannot prepare output: {source}")]
    Prepare {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("stage '{stage}' failed: {source}")]
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
    let options = Options::validate(&name, &entry.info.options, given).map_err(stage_err)?;
    if let Some(parent) = output.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(parent).map_err(|source| RunError::Prepare {
            path: parent.to_path_buf(),
            source,
        })?;
    }
    let staging = Staging::beside(output);
    if entry.info.output == OutputKind::Dir {
        std::fs::create_dir(staging.path()).map_err(|source| RunError::Prepare {
            path: staging.path().to_path_buf(),
            source,
        })?;
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
    Ok(summary)
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

/// A `pipeline.toml`: a `[pipeline]` table and one optional table of options per stage.
///
/// ```toml
/// [pipeline]
/// input = "data/dev-table"      # relative paths resolve against this file's directory
/// output = "runs/dev-table"     # the last stage's output
/// stages = ["ingest-llff", "densify"]
///
/// [densify]
/// points = 200000
/// ```
/// Intermediate results go to `<output>.stages/NN-<stage>/`, so each can be inspected
/// or used to rerun part of the chain.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct PipelineHeader {
    input: PathBuf,
    output: PathBuf,
    stages: Vec<String>,
}

pub fn run_pipeline(
    registry: &Registry,
    file: &Path,
    force: bool,
    ctx: &dyn Context,
) -> Result<Value, RunError> {
    let bad = |message: String| RunError::Pipeline {
        path: file.to_path_buf(),
        message,
    };
    let text = std::fs::read_to_string(file).map_err(|e| bad(e.to_string()))?;
    let mut doc: toml::Table = toml::from_str(&text).map_err(|e| bad(e.to_string()))?;
    let header = doc
        .remove("pipeline")
        .ok_or_else(|| bad("missing the [pipeline] table".to_owned()))?;
    let header: PipelineHeader = header
        .try_into()
        .map_err(|e| bad(format!("[pipeline]: {e}")))?;
    if header.stages.is_empty() {
        return Err(bad("[pipeline].stages is empty".to_owned()));
    }
    for key in doc.keys() {
        if !header.stages.contains(key) {
            return Err(bad(format!(
                "table [{key}] is not a stage listed in [pipeline].stages"
            )));
        }
    }
    let base = file.parent().unwrap_or_else(|| Path::new("."));
    let output = base.join(&header.output);
    let work = PathBuf::from(format!("{}.stages", output.display()));
    // Resolve every stage before running any, so a typo fails in a second, not an hour.
    let entries = header
        .stages
        .iter()
        .map(|s| registry.resolve(s))
        .collect::<Result<Vec<_>, _>>()?;
    // Every stage but the last hands a scene to the next; renders, exports and scores do not.
    let chain = header.stages.iter().zip(&entries);
    for (name, entry) in chain.take(header.stages.len() - 1) {
        let kind = entry.info.kind;
        if !matches!(
            kind,
            StageKind::Ingest | StageKind::Transform | StageKind::Train
        ) {
            return Err(bad(format!(
                "stage '{name}' ({kind:?}) does not write a scene, so no stage can follow it; \
                 put it last, or run it separately on an intermediate scene in {}",
                work.display()
            )));
        }
    }
    let mut input = base.join(&header.input);
    let mut done = Vec::new();
    for (i, (name, entry)) in header.stages.iter().zip(entries).enumerate() {
        let last = i + 1 == header.stages.len();
        let out = if last {
            output.clone()
        } else {
            work.join(format!("{:02}-{name}", i + 1))
        };
        let options = match doc.get(name) {
            Some(t) => toml_to_json(t)
                .as_object()
                .cloned()
                .ok_or_else(|| bad(format!("[{name}] must be a table")))?,
            None => Map::new(),
        };
        ctx.info(&format!(
            "[{}/{}] {name} -> {}",
            i + 1,
            header.stages.len(),
            out.display()
        ));
        let summary = run_stage(entry, &input, &out, &options, force, ctx)?;
        done.push(json!({ "stage": name, "output": out, "summary": summary }));
        input = out;
    }
    Ok(json!({ "output": output, "stages": done }))
}

fn toml_to_json(v: &toml::Value) -> Value {
    match v {
        toml::Value::String(s) => Value::String(s.clone()),
        toml::Value::Integer(i) => Value::from(*i),
        toml::Value::Float(f) => Value::from(*f),
        toml::Value::Boolean(b) => Value::Bool(*b),
        toml::Value::Datetime(d) => Value::String(d.to_string()),
        toml::Value::Array(a) => Value::Array(a.iter().map(toml_to_json).collect()),
        toml::Value::Table(t) => Value::Object(
            t.iter()
                .map(|(k, v)| (k.clone(), toml_to_json(v)))
                .collect(),
        ),
    }
}
