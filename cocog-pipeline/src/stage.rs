//! The one trait every stage implements, built in or loaded from a plugin.

use std::path::PathBuf;

use serde::{Deserialize, Serialize};
use serde_json::Value;

use crate::context::Context;
use crate::options::{OptionSpec, Options};
use crate::scene::SceneError;

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum StageKind {
    /// Dataset directory in, scene directory out.
    Ingest,
    /// Scene in, scene out (densify, prune, recentre, ...).
    Transform,
    Train,
    /// Scene in, one file out.
    Export,
    Render,
    Eval,
    /// Scene in, a dataset in another layout out.
    Convert,
}

impl StageKind {
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Ingest => "ingest",
            Self::Transform => "transform",
            Self::Train => "train",
            Self::Export => "export",
            Self::Render => "render",
            Self::Eval => "eval",
            Self::Convert => "convert",
        }
    }
}

/// What a stage creates at its output path.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum OutputKind {
    Dir,
    File,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StageInfo {
    pub name: String,
    pub kind: StageKind,
    pub output: OutputKind,
    /// Whether the stage reads the input scene's Gaussians: a pipeline refuses to run it on
    /// the scene a built-in ingest wrote, which has none. False when absent from a plugin's
    /// descriptor, so plugins built before the field are never refused by it.
    #[serde(default)]
    pub needs_gaussians: bool,
    pub description: String,
    #[serde(default)]
    pub options: Vec<OptionSpec>,
}

/// One run of a stage.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct StageRequest {
    /// A dataset directory (ingest) or a scene directory (everything else).
    pub input: PathBuf,
    /// A staging path next to the final output. The runner renames it into place only
    /// when the stage succeeds, so a failed or cancelled run leaves nothing behind.
    pub output: PathBuf,
    pub options: Options,
}

#[derive(Debug, thiserror::Error)]
pub enum StageError {
    /// Bad input data. The message names the file, the field and what was expected.
    #[error("{0}")]
    Input(String),
    #[error("{0}")]
    Options(String),
    #[error("cancelled")]
    Cancelled,
    #[error(transparent)]
    Scene(#[from] SceneError),
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error(transparent)]
    Other(#[from] Box<dyn std::error::Error + Send + Sync>),
}

impl StageError {
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Self::Io {
            path: path.into(),
            source,
        }
    }

    /// Wraps any library error (formats, engine, ...) for the host.
    pub fn other(e: impl std::error::Error + Send + Sync + 'static) -> Self {
        Self::Other(Box::new(e))
    }
}

pub trait Stage: Send + Sync {
    fn info(&self) -> StageInfo;

    /// Writes only under `req.output`; returns a JSON summary the CLI prints with `--json`.
    fn run(&self, req: &StageRequest, ctx: &dyn Context) -> Result<Value, StageError>;
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_descriptor_from_before_needs_gaussians_reads_as_not_needing_them() {
        let old = serde_json::json!({
            "name": "mine", "kind": "export", "output": "file", "description": "d"
        });
        let info: StageInfo = serde_json::from_value(old).unwrap();
        assert!(!info.needs_gaussians);
        assert_eq!((info.kind, info.options.len()), (StageKind::Export, 0));
        let new = serde_json::json!({
            "name": "mine", "kind": "export", "output": "file", "description": "d",
            "needs_gaussians": true
        });
        assert!(
            serde_json::from_value::<StageInfo>(new)
                .unwrap()
                .needs_gaussians
        );
    }
}
