//! Stages that go wrong on purpose: the host must turn each into a clean error.

use cocog_pipeline::{Context, OutputKind, Stage, StageError, StageInfo, StageKind, StageRequest};
use serde_json::Value;

struct Explode;
struct Refuse;
/// Shares its name with the built-in `eval`, to test that plugins never shadow silently.
struct ShadowEval;

fn info(name: &str, description: &str) -> StageInfo {
    StageInfo {
        name: name.to_owned(),
        kind: StageKind::Transform,
        output: OutputKind::Dir,
        needs_gaussians: false,
        description: description.to_owned(),
        options: Vec::new(),
    }
}

impl Stage for Explode {
    fn info(&self) -> StageInfo {
        info("explode", "panics halfway through writing its output")
    }

    fn run(&self, req: &StageRequest, ctx: &dyn Context) -> Result<Value, StageError> {
        ctx.info("explode: writing a partial output, then panicking");
        std::fs::write(req.output.join("partial.txt"), b"half")
            .map_err(|e| StageError::io(&req.output, e))?;
        panic!("deliberate panic inside a plugin stage");
    }
}

impl Stage for Refuse {
    fn info(&self) -> StageInfo {
        info("refuse", "always fails with an input error")
    }

    fn run(&self, req: &StageRequest, _ctx: &dyn Context) -> Result<Value, StageError> {
        Err(StageError::Input(format!(
            "{}/scene.json: field `views`: expected something this stage likes",
            req.input.display()
        )))
    }
}

impl Stage for ShadowEval {
    fn info(&self) -> StageInfo {
        let mut i = info("eval", "a stand-in for the built-in eval");
        i.kind = StageKind::Eval;
        i.output = OutputKind::File;
        i.options = vec![cocog_pipeline::OptionSpec::required(
            "gt",
            cocog_pipeline::OptionKind::Path,
            "ground truth",
        )];
        i
    }

    fn run(&self, _req: &StageRequest, _ctx: &dyn Context) -> Result<Value, StageError> {
        Err(StageError::Input(
            "the misbehaving plugin's eval ran".to_owned(),
        ))
    }
}

fn stages() -> Vec<Box<dyn Stage>> {
    vec![Box::new(Explode), Box::new(Refuse), Box::new(ShadowEval)]
}

cocog_pipeline::export_plugin!(name: "misbehaving", version: "0.0.1", stages: stages);
