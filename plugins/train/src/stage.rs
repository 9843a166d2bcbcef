//! The `train` pipeline stage: scene + points.ply in, scene + gaussians.ply out.

mod load;

use std::io::{BufWriter, Write};
use std::time::Instant;

use cocog_engine::GpuContext;
use cocog_pipeline::{
    Context, OptionSpec, OutputKind, Scene, Stage, StageError, StageInfo, StageKind, StageRequest,
};
use serde_json::{Value, json};

use crate::{TrainConfig, Trainer};

/// Vanilla 3DGS now; CoCoGaussian (`method = "cocog"`) is refused until it exists.
pub struct Train;

fn options() -> Vec<OptionSpec> {
    vec![
        OptionSpec::string(
            "method",
            "3dgs",
            "3dgs (vanilla INRIA) or cocog (not implemented yet)",
        ),
        OptionSpec::int("iterations", 7000, "optimisation steps, one view each"),
        OptionSpec::int(
            "downscale",
            1,
            "train on images shrunk by this factor (intrinsics scaled to match)",
        ),
        OptionSpec::int("seed", 0, "seeds the view order"),
        OptionSpec::int(
            "coc_gaussians",
            5,
            "CoC Gaussians per base Gaussian (only used by method cocog)",
        ),
        OptionSpec::int("sh_degree", 3, "largest spherical-harmonics degree, 0 to 3"),
    ]
}

/// Reads an int option in `[min, max]`; the runner already checked the type.
fn int(req: &StageRequest, name: &str, min: i64, max: i64) -> Result<i64, StageError> {
    let v = req
        .options
        .get_i64(name)
        .ok_or_else(|| StageError::Options(format!("stage 'train' needs int option '{name}'")))?;
    if !(min..=max).contains(&v) {
        return Err(StageError::Options(format!(
            "stage 'train' option '{name}' must be in {min}..={max}, got {v}"
        )));
    }
    Ok(v)
}

/// Losses of single views are noisy, so the log keeps ~10 lines for short runs and one every
/// 500 iterations for long ones (each reading costs a GPU sync).
fn log_interval(iterations: u32) -> u32 {
    (iterations / 10).clamp(1, 500)
}

impl Stage for Train {
    fn info(&self) -> StageInfo {
        StageInfo {
            name: "train".to_owned(),
            kind: StageKind::Train,
            output: OutputKind::Dir,
            description: "Optimise 3D Gaussians from the scene's points and train views".to_owned(),
            options: options(),
        }
    }

    fn run(&self, req: &StageRequest, ctx: &dyn Context) -> Result<Value, StageError> {
        match req.options.get_str("method").unwrap_or("3dgs") {
            "3dgs" => {}
            "cocog" => {
                return Err(StageError::Options(
                    "method 'cocog' (CoCoGaussian) is not implemented yet; use --method 3dgs"
                        .to_owned(),
                ));
            }
            other => {
                return Err(StageError::Options(format!(
                    "stage 'train' option 'method': unknown method '{other}' (use 3dgs)"
                )));
            }
        }
        let iterations = int(req, "iterations", 1, i64::from(u32::MAX))? as u32;
        let downscale = int(req, "downscale", 1, 64)? as u32;
        let seed = int(req, "seed", 0, i64::MAX)? as u64;
        // Validated so a typo fails now rather than when cocog lands.
        int(req, "coc_gaussians", 1, 64)?;
        let sh_degree = int(req, "sh_degree", 0, 3)? as u32;

        let mut scene = Scene::load(&req.input)?;
        scene.rebase(&req.input)?;
        let init = load::initial_gaussians(&scene, &req.input)?;
        let log_every = log_interval(iterations);
        let config = TrainConfig {
            iterations,
            max_sh_degree: sh_degree,
            seed,
            loss_every: log_every,
            ..TrainConfig::default()
        };
        let scratch = req.output.join(".downscaled");
        if downscale > 1 {
            std::fs::create_dir_all(&scratch).map_err(|e| StageError::io(&scratch, e))?;
        }
        let views = load::train_views(
            &scene,
            &req.input,
            downscale,
            config.background,
            &scratch,
            ctx,
        );
        if downscale > 1 {
            std::fs::remove_dir_all(&scratch).map_err(|e| StageError::io(&scratch, e))?;
        }
        let views = views?;

        let gpu = GpuContext::new().map_err(StageError::other)?;
        let adapter = gpu.adapter_name();
        ctx.info(&format!(
            "training {} Gaussians on {} views ({}×{}) for {iterations} iterations on {adapter}",
            init.len(),
            views.len(),
            views[0].camera.width,
            views[0].camera.height
        ));
        let mut trainer = Trainer::new(&gpu, &init, &views, config).map_err(StageError::other)?;
        drop(views);

        let log_path = req.output.join("train-log.jsonl");
        let file = std::fs::File::create(&log_path).map_err(|e| StageError::io(&log_path, e))?;
        let mut log = BufWriter::new(file);
        let start = Instant::now();
        let mut final_loss = None;
        for it in 1..=iterations {
            ctx.check_cancelled()?;
            let stats = trainer.step().map_err(StageError::other)?;
            if it % 10 == 0 || it == iterations {
                ctx.progress("train", u64::from(it), u64::from(iterations));
            }
            if let Some(loss) = stats.loss {
                final_loss = Some(loss);
                let elapsed = start.elapsed().as_secs_f64();
                let rate = f64::from(it) / elapsed.max(1e-9);
                let line = json!({
                    "iteration": it,
                    "loss": loss,
                    "gaussians": stats.num_gaussians,
                    "elapsed_s": elapsed,
                    "it_per_s": rate,
                });
                writeln!(log, "{line}").map_err(|e| StageError::io(&log_path, e))?;
                ctx.info(&format!(
                    "iteration {it}/{iterations}: loss {loss:.5}, {} Gaussians, {rate:.1} it/s",
                    stats.num_gaussians
                ));
            }
        }
        log.flush().map_err(|e| StageError::io(&log_path, e))?;
        let seconds = start.elapsed().as_secs_f64();

        let gaussians = trainer.gaussians().map_err(StageError::other)?;
        let ply = req.output.join("gaussians.ply");
        cocog_formats::ply::write_splats(&ply, &(&gaussians).into(), None)
            .map_err(StageError::other)?;
        scene.gaussians = Some("gaussians.ply".to_owned());
        scene.save(&req.output)?;
        Ok(json!({
            "iterations": iterations,
            "gaussians": gaussians.len(),
            "final_loss": final_loss,
            "seconds": seconds,
            "it_per_s": f64::from(iterations) / seconds.max(1e-9),
            "adapter": adapter,
        }))
    }
}
