//! `cocog run`: a chain of stages from a `pipeline.toml`, checkpointed and resumable.

use std::path::{Path, PathBuf};

use serde::Deserialize;
use serde_json::{Map, Value, json};

use crate::context::Context;
use crate::options::Options;
use crate::registry::{Provider, Registry, StageEntry};
use crate::runner::{RunError, RunHow, run_stage_with};
use crate::scene::Scene;
use crate::stage::{OutputKind, StageKind};

/// Options the pipeline sets itself; a resumed stage is "the same" whatever their values.
const RUNNER_OPTIONS: [&str; 3] = ["checkpoint_dir", "live_log", "resume"];

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
/// or used to rerun part of the chain; a training stage keeps its checkpoint and its log beside
/// its own output (`<its output>.checkpoint/`, `<its output>.train-log.jsonl`) until it
/// succeeds.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct PipelineHeader {
    input: PathBuf,
    output: PathBuf,
    stages: Vec<String>,
}

/// How `cocog run` treats earlier results.
#[derive(Clone, Copy, Debug, Default)]
pub struct RunMode {
    /// Replace outputs cocog wrote earlier.
    pub force: bool,
    /// Keep stages whose output exists with the same options and input, and continue an
    /// interrupted training stage from its checkpoint.
    pub resume: bool,
    /// Make every scene output self-contained (photos copied in).
    pub copy_images: bool,
}

/// One stage of the chain, with everything checked before anything runs.
struct Step<'a> {
    name: &'a str,
    entry: &'a StageEntry,
    options: Map<String, Value>,
    /// The options with defaults filled in, as a finished run's history records them.
    validated: Options,
    output: PathBuf,
    checkpoint: Option<PathBuf>,
}

pub fn run_pipeline(
    registry: &Registry,
    file: &Path,
    mode: RunMode,
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
    // Resolve and validate every stage before running any, so a typo in the last table
    // fails in a second, not after an hour of training.
    let mut steps = Vec::new();
    // The built-in ingest whose scene (no Gaussians) the next stage reads, if any. Only
    // built-in ingests are known to write none: a plugin's may import a trained model.
    let mut gaussian_free: Option<&str> = None;
    for (i, name) in header.stages.iter().enumerate() {
        let entry = registry.resolve(name)?;
        let last = i + 1 == header.stages.len();
        let kind = entry.info.kind;
        // Found now rather than when the stage starts, which may be after a training.
        if kind == StageKind::Ingest && i > 0 {
            return Err(bad(format!(
                "stage '{name}' reads a dataset, but it follows '{}', which writes a scene; \
                 an ingest stage can only come first",
                header.stages[i - 1]
            )));
        }
        if !last
            && !matches!(
                kind,
                StageKind::Ingest | StageKind::Transform | StageKind::Train
            )
        {
            return Err(bad(format!(
                "stage '{name}' ({kind:?}) does not write a scene, so no stage can follow it; \
                 put it last, or run it separately on an intermediate scene in {}",
                work.display()
            )));
        }
        if let Some(ingest) = gaussian_free.filter(|_| entry.info.needs_gaussians) {
            return Err(bad(format!(
                "stage '{name}' ({}) needs trained Gaussians, but no stage since '{ingest}' \
                 makes any (an ingest writes cameras and points only); put train before it",
                kind.as_str(),
            )));
        }
        let built_in = entry.provider == Provider::BuiltIn;
        if kind == StageKind::Ingest && built_in {
            gaussian_free = Some(name);
        } else if kind == StageKind::Train || !built_in {
            // A plugin may make Gaussians, whatever its kind.
            gaussian_free = None;
        }
        let mut options = match doc.get(name.as_str()) {
            Some(toml::Value::Table(t)) => {
                table_to_json(t).map_err(|e| bad(format!("[{name}] {e}")))?
            }
            Some(_) => return Err(bad(format!("[{name}] must be a table of options"))),
            None => Map::new(),
        };
        let validated =
            Options::validate(name, &entry.info.options, &options).map_err(|source| {
                RunError::Stage {
                    stage: name.clone(),
                    source,
                }
            })?;
        let step_out = if last {
            output.clone()
        } else {
            work.join(format!("{:02}-{name}", i + 1))
        };
        let checkpoint = beside(
            entry,
            &step_out,
            "checkpoint_dir",
            "checkpoint",
            &mut options,
        );
        beside(
            entry,
            &step_out,
            "live_log",
            "train-log.jsonl",
            &mut options,
        );
        steps.push(Step {
            name,
            entry,
            options,
            validated,
            output: step_out,
            checkpoint,
        });
    }
    let mut input = base.join(&header.input);
    let mut done = Vec::new();
    // Once a stage runs again, every later stage must too: its input changed.
    let mut rerun = !mode.resume;
    let count = steps.len();
    for (i, mut step) in steps.into_iter().enumerate() {
        let progress = format!("[{}/{count}] {}", i + 1, step.name);
        if !rerun && finished_before(&step, &input) {
            ctx.info(&format!(
                "{progress}: kept {} (same options and input)",
                step.output.display()
            ));
            done.push(json!({ "stage": step.name, "output": step.output, "kept": true }));
            input = step.output;
            continue;
        }
        rerun = true;
        if let Some(dir) = step
            .checkpoint
            .as_ref()
            .filter(|d| mode.resume && d.exists())
        {
            ctx.info(&format!("{progress}: resuming from {}", dir.display()));
            step.options
                .insert("resume".into(), Value::String(dir.display().to_string()));
        }
        ctx.info(&format!("{progress} -> {}", step.output.display()));
        // Under --resume an existing output is an earlier attempt's: cocog's to replace.
        let how = RunHow {
            force: mode.force || mode.resume,
            copy_images: mode.copy_images,
        };
        let summary = run_stage_with(step.entry, &input, &step.output, &step.options, &how, ctx)?;
        done.push(json!({ "stage": step.name, "output": step.output, "summary": summary }));
        input = step.output;
    }
    Ok(json!({ "output": output, "stages": done }))
}

/// Where a stage keeps an in-progress file that has an option naming it (`checkpoint_dir`,
/// `live_log`): `<output>.<suffix>` unless the file says otherwise; the option is filled in.
fn beside(
    entry: &StageEntry,
    output: &Path,
    option: &str,
    suffix: &str,
    options: &mut Map<String, Value>,
) -> Option<PathBuf> {
    if !entry.info.options.iter().any(|o| o.name == option) {
        return None;
    }
    let path = match options.get(option).and_then(Value::as_str) {
        Some(given) => PathBuf::from(given),
        None => {
            let path = PathBuf::from(format!("{}.{suffix}", output.display()));
            options.insert(option.into(), Value::String(path.display().to_string()));
            path
        }
    };
    Some(path)
}

/// Did an earlier run finish this stage from this input with these options? Only scene
/// outputs record that (in their history); files are always made again.
fn finished_before(step: &Step, input: &Path) -> bool {
    if step.entry.info.output != OutputKind::Dir {
        return false;
    }
    if step.checkpoint.as_ref().is_some_and(|c| c.exists()) {
        return false;
    }
    let Ok(scene) = Scene::load(&step.output) else {
        return false;
    };
    let Some(last) = scene.history.last() else {
        return false;
    };
    last.stage == step.entry.info.name
        && canonical(Path::new(&last.input)) == canonical(input)
        && same_options(&last.options, &step.validated)
}

fn same_options(recorded: &Value, wanted: &Options) -> bool {
    let mut recorded = recorded.as_object().cloned().unwrap_or_default();
    let mut wanted = wanted.0.clone();
    for k in RUNNER_OPTIONS {
        recorded.remove(k);
        wanted.remove(k);
    }
    recorded == wanted
}

/// TOML to JSON for stage options; NaN and infinities are refused here because JSON (the
/// plugin boundary) cannot carry them and would silently turn them into "unset".
fn table_to_json(t: &toml::Table) -> Result<Map<String, Value>, String> {
    t.iter()
        .map(|(k, v)| {
            Ok((
                k.clone(),
                value_to_json(v).map_err(|e| format!("option '{k}': {e}"))?,
            ))
        })
        .collect()
}

fn value_to_json(v: &toml::Value) -> Result<Value, String> {
    Ok(match v {
        toml::Value::String(s) => Value::String(s.clone()),
        toml::Value::Integer(i) => Value::from(*i),
        toml::Value::Float(f) if f.is_finite() => Value::from(*f),
        toml::Value::Float(f) => return Err(format!("{f} is not a finite number")),
        toml::Value::Boolean(b) => Value::Bool(*b),
        toml::Value::Datetime(d) => Value::String(d.to_string()),
        toml::Value::Array(a) => {
            Value::Array(a.iter().map(value_to_json).collect::<Result<_, _>>()?)
        }
        toml::Value::Table(t) => Value::Object(table_to_json(t)?),
    })
}

fn canonical(p: &Path) -> PathBuf {
    p.canonicalize().unwrap_or_else(|_| p.to_path_buf())
}
