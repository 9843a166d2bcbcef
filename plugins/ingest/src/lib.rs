//! Ingest stages: a dataset directory in, a cocog scene directory out.
//!
//! - `ingest-colmap`: `sparse/N/{cameras,images,points3D}.{bin,txt}` + `images/`.
//! - `ingest-llff`: `poses_bounds.npy` + `images/` (points from `sparse/` when present).
//! - `ingest-nerf`: `transforms.json` (or Blender's `transforms_{train,test}.json`).
//! - `ingest-photos`: a folder of photos, posed by running COLMAP (see [`photos`]).
//!
//! Options: `downscale` shrinks images by an integer factor (using `images_N/` when the dataset
//! has it, else resampling into the scene's `images/`); `hold` chooses the test split: test views
//! are those whose index in name order is a multiple of `hold`, and `hold = 0` trains on every
//! view. Unset, the dataset decides: per-frame splits of transforms.json, else the `hold=N`
//! marker file, else 8; a `hold=0` marker (BAD-Gaussians) trains on every view. A scene without
//! test views gets a warning that says how to make some. Image paths
//! that lead outside the dataset folder are refused unless `allow-outside` is set. A dataset
//! without SfM points (LLFF without `sparse/`, transforms.json) starts from 100k random points:
//! in the train frusta between the near/far bounds when known, else in INRIA's cube of side 2.6.
//! Ground-truth lens data in a dataset is not copied into the scene: training must not see it.

mod build;
mod fallback;
mod paths;
mod photos;
mod readers;

use cocog_formats::FormatError;
use cocog_pipeline::{
    Context, OptionKind, OptionSpec, OutputKind, Stage, StageError, StageInfo, StageKind,
    StageRequest,
};
use serde_json::Value;

use build::{Ingested, Settings, build_scene};

pub(crate) fn input_error(e: FormatError) -> StageError {
    match e {
        FormatError::Io { path, source } => StageError::io(path, source),
        other => StageError::Input(other.to_string()),
    }
}

#[derive(Clone, Copy)]
enum Layout {
    Colmap,
    Llff,
    Nerf,
    Photos,
}

struct Ingest(Layout);

fn common_options() -> Vec<OptionSpec> {
    vec![
        OptionSpec::int(
            "downscale",
            1,
            "shrink images by this integer factor (uses images_N/ when present)",
        ),
        OptionSpec::optional(
            "hold",
            OptionKind::Int,
            "test views are every hold-th view in name order; 0 = no test views (every view \
             trains); default: the dataset's split, else its hold=N marker, else 8",
        ),
        OptionSpec::bool(
            "allow-outside",
            false,
            "accept image paths that lead outside the dataset folder",
        ),
    ]
}

impl Stage for Ingest {
    fn info(&self) -> StageInfo {
        let (name, description) = match self.0 {
            Layout::Colmap => (
                "ingest-colmap",
                "Read a COLMAP dataset (sparse/N + images/) into a scene",
            ),
            Layout::Llff => (
                "ingest-llff",
                "Read an LLFF dataset (poses_bounds.npy + images/) into a scene",
            ),
            Layout::Nerf => (
                "ingest-nerf",
                "Read a NeRF dataset (transforms.json) into a scene",
            ),
            Layout::Photos => (
                "ingest-photos",
                "Run COLMAP on a folder of photos (or a dataset's images/) and read the \
                 result into a scene",
            ),
        };
        let mut options = common_options();
        if matches!(self.0, Layout::Photos) {
            options.extend(photos::options());
        }
        if matches!(self.0, Layout::Colmap) {
            options.push(OptionSpec::optional(
                "model",
                OptionKind::Int,
                "COLMAP model sparse/N to read (default: the one with most images)",
            ));
        }
        StageInfo {
            name: name.to_owned(),
            kind: StageKind::Ingest,
            output: OutputKind::Dir,
            needs_gaussians: false,
            description: description.to_owned(),
            options,
        }
    }

    fn run(&self, req: &StageRequest, ctx: &dyn Context) -> Result<Value, StageError> {
        let int = |name: &str, min: i64| -> Result<Option<u32>, StageError> {
            match req.options.get(name) {
                None => Ok(None),
                Some(v) => v
                    .as_i64()
                    .filter(|v| *v >= min && *v <= i64::from(u32::MAX))
                    .map(|v| Some(v as u32))
                    .ok_or_else(|| {
                        StageError::Options(format!(
                            "option '{name}': expected an integer ≥ {min}, got {v}"
                        ))
                    }),
            }
        };
        let settings = Settings {
            downscale: int("downscale", 1)?.unwrap_or(1),
            hold: int("hold", 0)?,
            allow_outside: match req.options.get("allow-outside") {
                None | Some(Value::Null) => false,
                Some(v) => v.as_bool().ok_or_else(|| {
                    StageError::Options(format!(
                        "option 'allow-outside': expected true or false, got {v}"
                    ))
                })?,
            },
        };
        let dataset = &req.input;
        if !dataset.is_dir() {
            return Err(StageError::Input(format!(
                "{}: dataset directory does not exist",
                dataset.display()
            )));
        }
        let data: Ingested = match self.0 {
            Layout::Colmap => readers::read_colmap(dataset, int("model", 0)?)?,
            Layout::Llff => readers::read_llff(dataset)?,
            Layout::Nerf => readers::read_nerf(dataset)?,
            Layout::Photos => return photos::run(req, &settings, ctx),
        };
        let (scene, summary) = build_scene(dataset, data, &settings, &req.output, ctx)?;
        ctx.info(&format!(
            "ingested {} views, {} cameras",
            scene.views.len(),
            scene.cameras.len()
        ));
        Ok(summary)
    }
}

/// The ingest stages, for the CLI to register.
pub fn stages() -> Vec<Box<dyn Stage>> {
    vec![
        Box::new(Ingest(Layout::Colmap)),
        Box::new(Ingest(Layout::Llff)),
        Box::new(Ingest(Layout::Nerf)),
        Box::new(Ingest(Layout::Photos)),
    ]
}
