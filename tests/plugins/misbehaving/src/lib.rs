//! Stages that go wrong on purpose: the host must turn each into a clean error.

use cocog_pipeline::{Context, OutputKind, Stage, StageError, StageInfo, StageKind, StageRequest};
use serde_json::Value;

struct Explode;
struct Refuse;

fn info(name: &str, description: &str) -> StageInfo {
    StageInfo {
        name: name.to_owned(),
        kind: StageKind::Transform,
        output: OutputKind::Dir,
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

fn stages() -> Vec<Box<dyn Stage>> {
    vec![Box::new(Explode), Box::new(Refuse)]
}

cocog_pipeline::export_plugin!(name: "misbehaving", version: "0.0.1", stages: stages);
