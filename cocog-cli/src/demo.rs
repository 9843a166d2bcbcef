//! `cocog demo`: the main job, end to end, on a scene that ships with cocog.
//!
//! The scene is generated, not downloaded: `cocog-synth` renders a small procedural
//! tabletop through a thin lens (defocused train views, sharp test views) in the
//! Deblur-NeRF layout. The demo then chains the stages exactly as a user would.

use std::path::Path;
use std::time::Instant;

use anyhow::{Context as _, Result, bail};
use cocog_pipeline::runner::run_stage;
use cocog_pipeline::{Context, Registry};
use cocog_synth::{SynthConfig, write_defocus_dataset};
use serde_json::{Map, Value, json};

use crate::cli::{DemoArgs, Global};
use crate::commands::print_result;

/// Marks a directory as the demo's own, so a rerun may replace it without --force.
const MARKER: &str = ".cocog-demo";

pub fn run(registry: &Registry, a: &DemoArgs, g: &Global, ctx: &dyn Context) -> Result<()> {
    let root = &a.output;
    if root.exists() {
        if !(g.force || root.join(MARKER).exists()) {
            bail!(
                "{}: exists and is not a cocog demo directory (use --force to replace it)",
                root.display()
            );
        }
        std::fs::remove_dir_all(root).with_context(|| format!("{}", root.display()))?;
    }
    std::fs::create_dir_all(root).with_context(|| format!("{}", root.display()))?;
    std::fs::write(root.join(MARKER), "").with_context(|| format!("{}", root.display()))?;

    let dataset = root.join("dataset");
    let started = Instant::now();
    let cfg = SynthConfig::default();
    ctx.info(&format!(
        "demo: rendering a {}-view {}x{} defocus dataset (thin lens, {} samples per view)",
        cfg.views, cfg.width, cfg.height, cfg.lens_samples
    ));
    write_defocus_dataset(&dataset, &cfg)
        .with_context(|| format!("generating the demo dataset in {}", dataset.display()))?;
    ctx.info(&format!(
        "demo: dataset ready in {:.1} s: {}",
        started.elapsed().as_secs_f64(),
        dataset.display()
    ));

    let chain: [(&str, &str, Value); 4] = [
        ("ingest-llff", "1-ingest", json!({})),
        ("densify", "2-densify", json!({ "points": 2000 })),
        // CoCoGaussian is not implemented yet: the demo trains plain 3DGS, briefly, so the
        // chain runs end to end even on a software adapter.
        (
            "train",
            "3-train",
            json!({ "method": "3dgs", "iterations": 200 }),
        ),
        ("export", "scene.ply", json!({ "format": "ply" })),
    ];
    let mut input = dataset;
    let mut ran = Vec::new();
    for (stage, out_name, options) in chain {
        let Ok(entry) = registry.resolve(stage) else {
            ctx.warn(&format!(
                "demo: stage '{stage}' is not in this build yet; stopping after {} stage(s). \
                 Results so far are in {}",
                ran.len(),
                root.display()
            ));
            break;
        };
        let output = root.join(out_name);
        let opts: Map<String, Value> = options.as_object().cloned().unwrap_or_default();
        ctx.info(&format!("demo: {stage} -> {}", output.display()));
        let summary = run_stage(entry, &input, &output, &opts, true, ctx)?;
        ran.push(json!({ "stage": stage, "output": output, "summary": summary }));
        input = output;
    }
    if ran.is_empty() {
        bail!("demo: no stage of the chain is available in this build");
    }
    // Score the sharp held-out views, so the demo ends with a number and shows how.
    let trained = root.join("3-train");
    if let (true, Ok(entry)) = (trained.exists(), registry.resolve("eval-scene")) {
        let metrics = root.join("metrics.json");
        ctx.info(&format!(
            "demo: eval-scene -> {} (same as `cocog eval {}`)",
            metrics.display(),
            trained.display()
        ));
        let scores = run_stage(entry, &trained, &metrics, &Map::new(), true, ctx)?;
        if !g.quiet {
            eprint!("{}", cocog_eval::format_table(&scores));
        }
        ran.push(json!({ "stage": "eval-scene", "output": metrics, "summary": scores }));
    }
    let summary = json!({ "root": root, "stages": ran });
    print_result(g, &summary, Path::new(&input))
}
