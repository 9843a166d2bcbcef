//! Maps each subcommand onto a stage name and its options, then runs it.

use std::fmt;
use std::path::Path;

use anyhow::{Context as _, Result};
use cocog_pipeline::pipeline::{RunMode, run_pipeline};
use cocog_pipeline::plugin::plugin_dirs;
use cocog_pipeline::runner::{RunHow, run_stage, run_stage_with};
use cocog_pipeline::{Context, Registry, StageEntry};
use serde_json::{Map, Value};

use crate::builtins;
use crate::cli::{
    Cli, Command, ConvertTarget, DatasetFormat, ExportFormat, Global, Method, SchedulePreset,
};
use crate::{demo, plugins};

/// A mistake on the command line that clap cannot see (exit code 2).
#[derive(Debug)]
pub struct UsageError(pub String);

impl fmt::Display for UsageError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for UsageError {}

/// Builds an options object from the flags the user actually gave.
macro_rules! options {
    ($($key:literal => $val:expr),* $(,)?) => {{
        #[allow(unused_mut)]
        let mut m = Map::new();
        $(if let Some(v) = $val { m.insert($key.to_owned(), Value::from(v)); })*
        m
    }};
}

pub fn dispatch(cli: &Cli, ctx: &dyn Context) -> Result<()> {
    let g = &cli.global;
    let registry = build_registry(g, ctx, matches!(cli.command, Command::Plugins))?;
    let run = |name: &str, input: &Path, output: &Path, options: Map<String, Value>| {
        run_named(&registry, name, input, output, &options, g, ctx)
    };
    match &cli.command {
        Command::Ingest(a) => {
            let name = match a.format {
                DatasetFormat::Colmap => "ingest-colmap",
                DatasetFormat::Llff => "ingest-llff",
                DatasetFormat::Nerf => "ingest-nerf",
                DatasetFormat::Photos => "ingest-photos",
            };
            let mut o = options! {
                "downscale" => a.downscale, "hold" => a.hold, "model" => a.model,
                "allow-outside" => a.allow_outside.then_some(true),
            };
            let p = &a.photos;
            let photos = options! {
                "colmap" => p.colmap.as_ref().map(|c| c.display().to_string()),
                "matcher" => p.matcher.clone(), "vocab-tree" => p.vocab_tree.as_ref().map(|c| c.display().to_string()),
                "camera-model" => p.camera_model.clone(),
                "camera-per-image" => p.camera_per_image.then_some(true),
                "max-features" => p.max_features, "dsp" => p.no_dsp.then_some(false),
                "max-ratio" => p.max_ratio, "guided-matching" => p.guided_matching.then_some(true),
                "gpu" => p.colmap_gpu.then_some(true), "min-registered" => p.min_registered,
                "narrow-baseline" => p.orbit.then_some(false),
                "free-intrinsics" => p.free_intrinsics.then_some(true),
                "focal-factor" => p.focal_factor,
            };
            if let (false, Some(key)) = (name == "ingest-photos", photos.keys().next()) {
                let flag = match key.as_str() {
                    "dsp" => "no-dsp",
                    "gpu" => "colmap-gpu",
                    "narrow-baseline" => "orbit",
                    k => k,
                };
                anyhow::bail!("--{flag} is an option of `cocog ingest photos` only");
            }
            o.extend(photos);
            if name == "ingest-photos" {
                // Beside the output, not in it: the runner discards a failed run's staging
                // folder, and a failed COLMAP run is when the log matters most.
                let mut log = a.output.clone().into_os_string();
                log.push(".colmap.log");
                o.insert(
                    "log".into(),
                    Value::from(log.to_string_lossy().into_owned()),
                );
            }
            run(name, &a.dataset, &a.output, o)
        }
        Command::Densify(a) => {
            let o = options! {
                "points" => a.points, "seed" => a.seed, "max-distance" => a.max_distance,
            };
            run("densify", &a.io.scene, &a.io.output, o)
        }
        Command::Train(a) => {
            let method = a.method.map(|m| match m {
                Method::Cocog => "cocog",
                Method::Gs3d => "3dgs",
            });
            // Beside the output, not in it: the runner discards a failed run's staging folder,
            // and the checkpoint is what lets an interrupted run continue. The log sits there
            // too, under a name the user can `tail -f` while the output does not exist yet.
            let beside = |suffix: &str| {
                let mut p = a.io.output.clone().into_os_string();
                p.push(suffix);
                std::path::PathBuf::from(p).display().to_string()
            };
            let mut o = options! {
                "method" => method, "iterations" => a.iterations,
                "coc_gaussians" => a.coc_gaussians, "downscale" => a.downscale, "seed" => a.seed,
                "coc_variant" => a.coc_variant.clone(), "blur_start" => a.blur_start,
                "composite_start" => a.composite_start,
                "compositor_channels" => a.compositor_channels,
                "coc_centred" => a.coc_centred,
                "coc_modulate_base" => a.coc_sharp_base.then_some(false),
                "coc_head_init" => a.coc_head_init,
                "kernel_lr" => a.kernel_lr,
                "focus_init" => a.focus_init.clone().filter(|f| !matches!(f.as_str(), "mean" | "estimate")),
                "focus_estimate" => (a.focus_init.as_deref() == Some("estimate")).then_some(true),
                "refocus_every" => a.refocus_every, "refocus_until" => a.refocus_until,
                "sh_degree" => a.sh_degree,
                "random_background" => a.random_background.then_some(true),
                "background" => a.background.clone(),
                "resume" => a.resume.as_ref().map(|p| p.display().to_string()),
                "checkpoint_every" => a.checkpoint_every,
                "checkpoint_dir" => Some(beside(".checkpoint")),
                "live_log" => Some(beside(".train-log.jsonl")), "eval_every" => a.eval_every,
            };
            let s = &a.schedule;
            let preset = s.schedule.map(|p| match p {
                SchedulePreset::Auto => "auto",
                SchedulePreset::Deblur => "deblur",
                SchedulePreset::Inria => "inria",
            });
            o.extend(options! {
                "schedule" => preset, "scene_scale" => s.scene_scale.clone(),
                "densify_from" => s.densify_from, "densify_until" => s.densify_until,
                "densify_every" => s.densify_every, "densify_grad" => s.densify_grad,
                "percent_dense" => s.percent_dense, "prune_opacity" => s.prune_opacity,
                "prune_large" => s.prune_large, "opacity_reset_every" => s.opacity_reset_every,
                "sh_every" => s.sh_every, "depth_prune_range" => s.depth_prune_range,
                "lambda_dssim" => s.lambda_dssim, "position_lr" => s.position_lr,
                "add_points_at" => s.add_points_at, "add_points_max" => s.add_points_max,
                "add_points_distance" => s.add_points_distance,
                "add_points_frame" => s.add_points_frame.clone(),
            });
            run("train", &a.io.scene, &a.io.output, o)
        }
        Command::Prune(a) => {
            let o = options! { "threshold" => a.threshold, "range" => a.range };
            run("prune", &a.io.scene, &a.io.output, o)
        }
        Command::Export(a) => {
            let format = match a.format {
                ExportFormat::Ply => "ply",
                ExportFormat::Glb => "glb",
                ExportFormat::Spz => "spz",
            };
            run(
                "export",
                &a.scene,
                &a.output,
                options! { "format" => Some(format) },
            )
        }
        Command::Render(a) => {
            let o = options! {
                "split" => a.split.clone(), "downscale" => a.downscale,
                "background" => a.background.clone(),
                "focus_distance" => a.focus_distance.clone(), "focus_at" => a.focus_at.clone(),
                "as_photographed" => a.as_photographed.then_some(true),
                "aperture" => a.aperture, "composite" => a.composite.clone(),
                "views" => a.views.clone(), "depth" => a.depth.then_some(true),
                "camera" => a.camera.as_ref().map(|p| p.display().to_string()),
            };
            match &a.focus_sweep {
                Some(sweep) => crate::sweep::run(&registry, a, sweep, o, g, ctx),
                None => run("render", &a.io.scene, &a.io.output, o),
            }
        }
        Command::Eval(a) => eval(&registry, a, g, ctx),
        Command::Convert(a) => {
            let to = match a.to {
                ConvertTarget::Colmap => "colmap",
                ConvertTarget::Nerf => "nerf",
            };
            run(
                "convert",
                &a.scene,
                &a.output,
                options! { "to" => Some(to) },
            )
        }
        Command::Stage(a) => {
            let mut o = Map::new();
            for kv in &a.set {
                let (k, v) = kv
                    .split_once('=')
                    .ok_or_else(|| UsageError(format!("--set {kv}: expected KEY=VALUE")))?;
                let value = serde_json::from_str(v).unwrap_or_else(|_| Value::from(v));
                o.insert(k.to_owned(), value);
            }
            run(&a.name, &a.input, &a.output, o)
        }
        Command::Run(a) => {
            let mode = RunMode {
                force: g.force,
                resume: a.resume,
                copy_images: g.copy_images,
            };
            let summary = match run_pipeline(&registry, &a.pipeline, mode, ctx) {
                Ok(s) => s,
                // Mistakes in the file already name it.
                Err(e @ cocog_pipeline::runner::RunError::Pipeline { .. }) => return Err(e.into()),
                // The stage's own advice names its --resume; in a pipeline the run's is the one.
                Err(e) if e.is_cancelled() => {
                    ctx.warn(&format!(
                        "continue the pipeline with `cocog run {} --resume`: finished stages \
                         are kept and an interrupted training resumes from its checkpoint",
                        a.pipeline.display()
                    ));
                    return Err(e.into());
                }
                Err(e) => {
                    return Err(
                        anyhow::Error::new(e).context(format!("pipeline {}", a.pipeline.display()))
                    );
                }
            };
            let out = summary.get("output").and_then(Value::as_str).unwrap_or("");
            print_result(g, &summary, Path::new(out))
        }
        Command::Plugins => plugins::list(&registry, g.json, g.verbose),
        Command::Demo(a) => demo::run(&registry, a, g, ctx),
        Command::Bench(a) => bench(a, g, ctx),
        Command::Lens(a) => crate::lens::run(a, g),
    }
}

fn bench(a: &crate::cli::BenchArgs, g: &Global, ctx: &dyn Context) -> Result<()> {
    if a.iterations == 0 || a.downscale == 0 || a.sh_degree > 3 {
        return Err(UsageError(
            "bench needs --iterations ≥ 1, --downscale ≥ 1 and --sh-degree 0..=3".to_owned(),
        )
        .into());
    }
    let opts = cocog_train::BenchOptions {
        downscale: a.downscale,
        iterations: a.iterations,
        warmup: a.warmup,
        resume: a.resume.clone(),
        max_sh_degree: a.sh_degree,
        kernels: a.kernels,
        coc: match a.method {
            crate::cli::Method::Gs3d => None,
            crate::cli::Method::Cocog => {
                let mut c =
                    cocog_train::CocTrainConfig::named(&a.coc_variant).map_err(UsageError)?;
                let copies = a.coc_gaussians.unwrap_or(c.net.copies);
                if !(1..=16).contains(&copies) || !(1..=256).contains(&a.compositor_channels) {
                    return Err(UsageError(
                        "bench needs --coc-gaussians 1..=16 and --compositor-channels 1..=256"
                            .to_owned(),
                    )
                    .into());
                }
                c.net.copies = copies;
                if let Some(centred) = a.coc_centred {
                    c.net.centred = centred;
                }
                c.compositor_channels = a.compositor_channels;
                Some(c)
            }
        },
    };
    let report = match (&a.scene, a.synthetic) {
        (_, Some(gaussians)) => {
            let spec = cocog_train::SyntheticSpec {
                gaussians,
                width: a.size.map_or(1920, |s| s.0),
                height: a.size.map_or(1080, |s| s.1),
                views: a.views.unwrap_or(8),
                seed: a.seed.unwrap_or(0),
                zoom: a.zoom.unwrap_or(1.0),
                write_to: a.write_workload.clone(),
            };
            cocog_train::run_bench_synthetic(&spec, &opts, ctx)
                .with_context(|| format!("benchmarking {gaussians} random Gaussians"))?
        }
        (Some(scene), None) => cocog_train::run_bench(scene, &opts, ctx)
            .with_context(|| format!("benchmarking {}", scene.display()))?,
        (None, None) => {
            return Err(UsageError("bench needs a SCENE or --synthetic N".to_owned()).into());
        }
    };
    if g.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print!("{}", report.table());
    }
    Ok(())
}

fn build_registry(g: &Global, ctx: &dyn Context, listing: bool) -> Result<Registry> {
    let mut registry = Registry::new();
    builtins::register(&mut registry);
    registry.load_plugins(&plugin_dirs(&g.plugin_path));
    for (path, why) in &registry.skipped {
        ctx.debug(&format!(
            "not a plugin, not opened: {}: {why}",
            path.display()
        ));
    }
    // `cocog plugins` reports broken libraries itself, in its table.
    if !listing {
        for e in &registry.load_errors {
            ctx.warn(&format!("skipping plugin: {e}"));
        }
    }
    for spec in &g.use_plugin {
        registry.use_plugin(spec)?;
    }
    Ok(registry)
}

/// Finds a stage: built in, or from a plugin.
pub fn resolve<'a>(registry: &'a Registry, name: &str) -> Result<&'a StageEntry> {
    Ok(registry.resolve(name)?)
}

pub fn run_named(
    registry: &Registry,
    name: &str,
    input: &Path,
    output: &Path,
    options: &Map<String, Value>,
    g: &Global,
    ctx: &dyn Context,
) -> Result<()> {
    let entry = resolve(registry, name)?;
    let how = RunHow {
        force: g.force,
        copy_images: g.copy_images,
    };
    let summary = run_stage_with(entry, input, output, options, &how, ctx)?;
    print_result(g, &summary, output)
}

fn eval(
    registry: &Registry,
    a: &crate::cli::EvalArgs,
    g: &Global,
    ctx: &dyn Context,
) -> Result<()> {
    match (&a.scene, &a.pred, &a.gt) {
        (None, Some(pred), Some(gt)) => {
            // The prediction folder is the user's: without -o the scores go to stdout only.
            let scratch = match &a.output {
                Some(_) => None,
                None => Some(tempfile::tempdir().context("a scratch folder for the scores")?),
            };
            let output = match (&a.output, &scratch) {
                (Some(o), _) => o.clone(),
                (None, Some(t)) => t.path().join("metrics.json"),
                (None, None) => unreachable!("a scratch folder exists without -o"),
            };
            let o = options! {
                "gt" => Some(gt.display().to_string()), "lpips" => a.lpips.clone(),
                "vgg" => a.vgg.then_some(true), "threads" => a.threads,
                "lpips_weights" => a.lpips_weights.as_ref().map(|p| p.display().to_string()),
            };
            let entry = resolve(registry, "eval")?;
            let summary = run_stage(entry, pred, &output, &o, g.force, ctx)?;
            if scratch.is_some() {
                if g.json {
                    println!("{}", serde_json::to_string_pretty(&summary)?);
                } else {
                    print!("{}", cocog_eval::format_table(&summary));
                }
                return Ok(());
            }
            if !g.quiet {
                eprint!("{}", cocog_eval::format_table(&summary));
            }
            print_result(g, &summary, &output)
        }
        (Some(scene), None, _) => {
            let output = a
                .output
                .clone()
                .unwrap_or_else(|| scene.join("metrics.json"));
            let o = options! {
                "split" => a.split.clone(), "downscale" => a.downscale,
                "lpips" => a.lpips.clone(), "vgg" => a.vgg.then_some(true),
                "threads" => a.threads,
                "lpips_weights" => a.lpips_weights.as_ref().map(|p| p.display().to_string()),
            };
            // Re-scoring a scene replaces its own default metrics file.
            let force = g.force || a.output.is_none();
            let entry = resolve(registry, "eval-scene")?;
            let summary = run_stage(entry, scene, &output, &o, force, ctx)?;
            if !g.quiet {
                eprint!("{}", cocog_eval::format_table(&summary));
            }
            print_result(g, &summary, &output)
        }
        _ => Err(UsageError("eval needs a SCENE, or --pred DIR --gt DIR".to_owned()).into()),
    }
}

/// The output path on stdout, or with `--json` the stage's summary, which then names the
/// output too (`output`), so a script needs nothing else to find it.
pub fn print_result(g: &Global, summary: &Value, output: &Path) -> Result<()> {
    if g.json {
        let mut summary = summary.clone();
        if let Some(map) = summary.as_object_mut() {
            map.insert(
                "output".to_owned(),
                Value::from(output.display().to_string()),
            );
        }
        println!("{}", serde_json::to_string_pretty(&summary)?);
    } else {
        println!("{}", output.display());
    }
    Ok(())
}
