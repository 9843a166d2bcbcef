//! The `train` pipeline stage: scene + points.ply in, scene + gaussians.ply out.

mod finite;
pub(crate) mod load;
mod log;
mod schedule;
mod session;
mod test_eval;

use std::path::PathBuf;

use cocog_engine::GpuContext;
use cocog_pipeline::{
    Context, OptionKind, OptionSpec, OutputKind, Scene, Split, Stage, StageError, StageInfo,
    StageKind, StageRequest,
};
use serde_json::{Value, json};

use cocog_engine::coc::CocVariant;

use crate::{CocCheckpoint, CocTrainConfig, TrainConfig, TrainState, Trainer};
use schedule::Schedule;
use test_eval::TestViews;

/// The lens model's file in a cocog output.
const LENS_MODEL: &str = "lens-model.safetensors";

/// CoCoGaussian (`method = "cocog"`) or vanilla 3DGS (`"3dgs"`, the same loop without CoC sets).
pub struct Train;

fn options() -> Vec<OptionSpec> {
    let mut specs = vec![
        OptionSpec::optional(
            "method",
            OptionKind::String,
            "cocog (CoCoGaussian: learns the defocus of each photo, keeps sharp base Gaussians; \
             the default) or 3dgs (vanilla INRIA, about 2.8× cheaper a step); a resumed run \
             keeps its checkpoint's",
        )
        .one_of(&["cocog", "3dgs"]),
        OptionSpec::optional(
            "coc_variant",
            OptionKind::String,
            "cocog: paper (aperture, scaling, directions from h_θ; 5 copies, h_θ from 2000, F \
             from 6000; the best on the dev scenes), lens (a thin lens per photo: the CoC radius \
             from that photo's learned aperture and focus, β and directions from h_θ; 5 copies \
             centred on their base, h_θ from 1000, F from 6000) or code (the released code: free \
             offsets gated by |1/d - 1/d_F| in the scene's units, 4 copies, h_θ and F from 1500; \
             on dev-table its first 100 blurred steps cost the base 2 dB); a resumed run keeps \
             its checkpoint's. Runs shorter than 7000 iterations start h_θ and F at the same \
             shares of the run unless either start is given",
        )
        .one_of(&["paper", "lens", "code"]),
        OptionSpec::int(
            "blur_start",
            0,
            "cocog: first iteration through the CoC sets (plain 3DGS before); 0 = the variant's \
             (fitted to runs shorter than 7000 iterations; a resumed run's own)",
        )
        .at_least(0.0),
        OptionSpec::int(
            "composite_start",
            0,
            "cocog: first iteration composited by the CNN F (the sets are averaged before); \
             0 = the variant's (fitted like blur_start)",
        )
        .at_least(0.0),
        OptionSpec::optional(
            "coc_centred",
            OptionKind::Bool,
            "cocog: subtract the copies' mean offset, so the CoC Gaussians sit around their base \
             (neither published source does); default: on for lens, off for code and paper",
        ),
        OptionSpec::bool(
            "coc_modulate_base",
            true,
            "cocog: modulate the base set's scale and rotation too, as the released code does \
             (test views render the base unmodulated)",
        ),
        OptionSpec::float(
            "kernel_lr",
            1e-3,
            "cocog: initial learning rate of h_θ, F and the focus distances at the blur start, \
             decaying exponentially at 100× per run length (27× by the end of a 7000-iteration \
             run from 2000) (1e-3 in both sources; short runs learn the lens faster with more)",
        )
        .between(1e-12, 1.0),
        OptionSpec::optional(
            "focus_init",
            OptionKind::Path,
            "cocog: start each training photo's focus distance from a known one: a \
             transforms.json whose frames carry focus_distance_m in scene units (the cocog \
             bench, the demo dataset); default: the mean camera-to-Gaussian distance",
        ),
        OptionSpec::bool(
            "focus_estimate",
            false,
            "cocog: without focus_init, estimate each photo's focus at the blur start by depth \
             from defocus (the warm-up render blurred by a thin lens, fitted to the photo) \
             instead of the mean camera-to-Gaussian distance",
        ),
        OptionSpec::int(
            "refocus_every",
            0,
            "cocog, experimental: every N iterations after the blur start, estimate each \
             photo's focus again by depth from defocus against the current base Gaussians and \
             replace the learned one (0: never; the gradient alone moves a focus little, but \
             on a two-plane test scene half the runs locked every photo onto one plane)",
        )
        .at_least(0.0),
        OptionSpec::int(
            "refocus_until",
            0,
            "cocog: last iteration refocus_every applies to (0: the end of the run)",
        )
        .at_least(0.0),
        OptionSpec::optional(
            "coc_head_init",
            OptionKind::Float,
            "cocog: scale of h_θ's initial head weights (1 = PyTorch's default, as both sources; \
             smaller starts the CoC Gaussians near their base); default: 0.01 for lens, 1 for \
             code and paper",
        )
        .between(0.0, 10.0),
        OptionSpec::int(
            "compositor_channels",
            64,
            "cocog: hidden channels of F (64 in the paper; fewer train faster on a CPU)",
        )
        .between(1.0, 256.0),
        OptionSpec::int("iterations", 7000, "optimisation steps, one view each")
            .between(1.0, f64::from(u32::MAX)),
        OptionSpec::int(
            "downscale",
            1,
            "train on images shrunk by this factor (intrinsics scaled to match)",
        )
        .between(1.0, 64.0),
        OptionSpec::int(
            "seed",
            0,
            "seeds the view order, splits and random backgrounds",
        )
        .at_least(0.0),
        OptionSpec::int(
            "coc_gaussians",
            0,
            "cocog: CoC Gaussians M per base Gaussian; 0 = the variant's (code 4, paper 5)",
        )
        .between(0.0, 16.0),
        OptionSpec::int("sh_degree", 3, "largest spherical-harmonics degree, 0 to 3")
            .between(0.0, 3.0),
        OptionSpec::string(
            "background",
            "0,0,0",
            "black, white or r,g,b in 0..1: what photos with alpha are composited over and \
             what the Gaussians render over (render and eval with the same --background)",
        ),
        OptionSpec::bool(
            "random_background",
            false,
            "composite every training render over a random colour (discourages transparent \
             floaters); evaluation renders stay black",
        ),
        OptionSpec::optional(
            "resume",
            OptionKind::Path,
            "continue from a checkpoint: a train output (its checkpoint/), a checkpoint \
             directory, or its state.safetensors",
        ),
        OptionSpec::optional(
            "checkpoint_dir",
            OptionKind::Path,
            "where to keep a checkpoint while training (every checkpoint_every iterations and \
             on Ctrl-C), removed when the run succeeds; the CLI uses OUTPUT.checkpoint",
        ),
        OptionSpec::int(
            "checkpoint_every",
            1000,
            "iterations between checkpoints in checkpoint_dir; 0 only on interruption",
        )
        .at_least(0.0),
        OptionSpec::optional(
            "live_log",
            OptionKind::Path,
            "where to write train-log.jsonl while training, line by line (tail -f it); \
             copied into the output when the run succeeds, then removed; kept with the \
             checkpoint when it is interrupted. Default: inside the output only; the CLI uses \
             OUTPUT.train-log.jsonl",
        ),
        OptionSpec::int(
            "eval_every",
            0,
            "score the test views (PSNR, SSIM) every N iterations and at the end, into the \
             log as `eval` records; 0 never",
        )
        .at_least(0.0),
    ];
    specs.extend(schedule::options());
    specs
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

/// The log keeps ~10 lines for short runs and one every 100 iterations for long ones: single
/// views' PSNRs scatter by several dB, so spotting a collapse takes many readings, and one
/// every 100 iterations (a GPU sync and two image reads) costs well under 1% of a step's time.
fn log_interval(iterations: u32) -> u32 {
    (iterations / 10).clamp(1, 100)
}

/// The method to train: option `method`, else a resumed checkpoint's, else cocog.
fn method<'a>(req: &'a StageRequest, resumed: Option<&TrainState>) -> &'a str {
    match (req.options.get_str("method"), resumed) {
        (Some(m), _) => m,
        (None, Some(s)) if s.coc.is_none() => "3dgs",
        (None, _) => "cocog",
    }
}

/// CoCoGaussian's configuration when `method` is cocog, `None` for 3dgs. A resumed lens model
/// lends its variant and starts to options not given.
fn coc_config(
    req: &StageRequest,
    iterations: u32,
    method: &str,
    resumed: Option<&CocCheckpoint>,
) -> Result<Option<CocTrainConfig>, StageError> {
    match method {
        "3dgs" => return Ok(None),
        "cocog" => {}
        other => {
            return Err(StageError::Options(format!(
                "stage 'train' option 'method': unknown method '{other}' (use cocog or 3dgs)"
            )));
        }
    }
    let name = req
        .options
        .get_str("coc_variant")
        .or(resumed.map(|k| k.variant.as_str()))
        .unwrap_or("paper");
    let variant = CocVariant::parse(name).ok_or_else(|| {
        StageError::Options(format!(
            "stage 'train' option 'coc_variant': unknown variant '{name}' (use code, paper or \
             lens)"
        ))
    })?;
    let mut c = CocTrainConfig::new(variant);
    let copies = int(req, "coc_gaussians", 0, 16)? as u32;
    if copies > 0 {
        c.net.copies = copies;
    }
    let limit = i64::from(u32::MAX);
    let blur = int(req, "blur_start", 0, limit)? as u32;
    let composite = int(req, "composite_start", 0, limit)? as u32;
    match (blur, composite, resumed) {
        // A resumed run keeps its starts: they were fitted to the length it was started with.
        (0, 0, Some(k)) => {
            if let Some([b, f]) = k.starts {
                (c.blur_start, c.composite_start) = (b, f);
            }
        }
        (0, 0, None) => c.fit_to(iterations),
        // A start given explicitly leaves the other at the variant's.
        _ => {
            if blur > 0 {
                c.blur_start = blur;
            }
            if composite > 0 {
                c.composite_start = composite;
            }
        }
    }
    c.compositor_channels = int(req, "compositor_channels", 1, 256)? as u32;
    if let Some(centred) = req.options.get_bool("coc_centred") {
        c.net.centred = centred;
    }
    c.net.modulate_base = req.options.get_bool("coc_modulate_base").unwrap_or(true);
    if let Some(head_init) = req.options.get_f64("coc_head_init") {
        if !(0.0..=10.0).contains(&head_init) {
            return Err(StageError::Options(format!(
                "stage 'train' option 'coc_head_init' must be in 0..=10, got {head_init}"
            )));
        }
        c.head_init_scale = head_init as f32;
    }
    let lr = req.options.get_f64("kernel_lr").unwrap_or(1e-3);
    if !(lr > 0.0 && lr <= 1.0) {
        return Err(StageError::Options(format!(
            "stage 'train' option 'kernel_lr' must be in (0, 1], got {lr}"
        )));
    }
    c.kernel_lr_final *= lr / c.kernel_lr_init;
    c.kernel_lr_init = lr;
    c.estimate_focus = req.options.get_bool("focus_estimate").unwrap_or(false);
    c.refocus_every = int(req, "refocus_every", 0, limit)? as u32;
    c.refocus_until = match int(req, "refocus_until", 0, limit)? as u32 {
        0 => iterations,
        until => until,
    };
    if c.blur_start > iterations {
        return Err(StageError::Options(format!(
            "stage 'train': blur_start {} is past the last iteration ({iterations}): the run \
             would be plain 3DGS; lower blur_start or use --method 3dgs",
            c.blur_start
        )));
    }
    Ok(Some(c))
}

/// What the options ask for, checked before any file is read.
struct Plan {
    config: TrainConfig,
    /// The scene scale is still unresolved in `config` (it needs the cameras and points).
    schedule: Schedule,
    downscale: u32,
    resume: Option<PathBuf>,
    checkpoint_dir: Option<PathBuf>,
    checkpoint_every: u32,
    live_log: Option<PathBuf>,
    eval_every: u32,
}

fn plan(req: &StageRequest, resumed: Option<&TrainState>) -> Result<Plan, StageError> {
    let iterations = int(req, "iterations", 1, i64::from(u32::MAX))? as u32;
    let method = method(req, resumed);
    let coc = coc_config(
        req,
        iterations,
        method,
        resumed.and_then(|s| s.coc.as_ref()),
    )?;
    let schedule = Schedule::from_request(req, method)?;
    Ok(Plan {
        config: TrainConfig {
            densify: Some(schedule.densify.clone()),
            sh_degree_interval: schedule.sh_interval,
            lambda_dssim: schedule.lambda_dssim,
            position_lr_init: schedule.position_lr[0],
            position_lr_final: schedule.position_lr[1],
            iterations,
            max_sh_degree: int(req, "sh_degree", 0, 3)? as u32,
            seed: int(req, "seed", 0, i64::MAX)? as u64,
            loss_every: log_interval(iterations),
            random_background: req.options.get_bool("random_background").unwrap_or(false),
            background: cocog_pipeline::parse_colour(
                "background",
                req.options.get_str("background").unwrap_or("0,0,0"),
            )?,
            coc,
            ..TrainConfig::default()
        },
        schedule,
        downscale: int(req, "downscale", 1, 64)? as u32,
        resume: req.options.get_path("resume"),
        checkpoint_dir: req.options.get_path("checkpoint_dir"),
        checkpoint_every: int(req, "checkpoint_every", 0, i64::from(u32::MAX))? as u32,
        live_log: req.options.get_path("live_log"),
        eval_every: int(req, "eval_every", 0, i64::from(u32::MAX))? as u32,
    })
}

/// An unfinished run's checkpoint where this run would keep its own: only a run that
/// resumes from it may overwrite it (and remove it when it succeeds).
fn refuse_foreign_checkpoint(plan: &Plan) -> Result<(), StageError> {
    let Some(dir) = plan.checkpoint_dir.as_ref().filter(|d| d.exists()) else {
        return Ok(());
    };
    let canonical = |p: &std::path::Path| p.canonicalize().unwrap_or_else(|_| p.to_path_buf());
    let resumes_it = plan
        .resume
        .as_deref()
        .is_some_and(|r| canonical(r).starts_with(canonical(dir)));
    if resumes_it {
        return Ok(());
    }
    // Exit 1 like "output already exists": the state of the output, not a flag, refuses it.
    Err(StageError::Input(format!(
        "{} holds the checkpoint of a run that did not finish (interrupted, or stopped by an \
         error); continue it with --resume {} (in a \
         pipeline: cocog run --resume), or remove it to start afresh",
        dir.display(),
        dir.display()
    )))
}

/// The checkpoint option `resume` names, read before the plan: its method, variant and
/// starts are the defaults of a resumed run.
fn load_resume(req: &StageRequest) -> Result<Option<TrainState>, StageError> {
    req.options
        .get_path("resume")
        .map(|path| TrainState::load(&path).map_err(|e| StageError::Input(e.to_string())))
        .transpose()
}

/// `state`, refused if it cannot continue this run.
fn check_resume(plan: &Plan, state: Option<TrainState>) -> Result<Option<TrainState>, StageError> {
    let (Some(path), Some(state)) = (&plan.resume, state) else {
        return Ok(None);
    };
    let what = format!("option 'resume' ({})", path.display());
    if let (Some(k), None) = (&state.coc, &plan.config.coc) {
        return Err(StageError::Options(format!(
            "{what}: the checkpoint is a --method cocog run ({} variant); continue it with \
             --method cocog (its lens model would be dropped otherwise)",
            k.variant
        )));
    }
    if state.downscale != plan.downscale {
        return Err(StageError::Options(format!(
            "{what}: the checkpoint was trained at downscale {}, this run asks for {}",
            state.downscale, plan.downscale
        )));
    }
    if state.iteration >= plan.config.iterations {
        return Err(StageError::Options(format!(
            "{what}: the checkpoint is already at iteration {}; ask for more --iterations",
            state.iteration
        )));
    }
    if state.params.sh_degree > plan.config.max_sh_degree {
        return Err(StageError::Options(format!(
            "{what}: the checkpoint has SH degree {}, above option 'sh_degree' = {}",
            state.params.sh_degree, plan.config.max_sh_degree
        )));
    }
    Ok(Some(state))
}

impl Stage for Train {
    fn info(&self) -> StageInfo {
        StageInfo {
            name: "train".to_owned(),
            kind: StageKind::Train,
            output: OutputKind::Dir,
            needs_gaussians: false,
            description: "Optimise 3D Gaussians from the scene's points and train views; \
                          writes gaussians.ply, checkpoint/ and train-log.jsonl"
                .to_owned(),
            options: options(),
        }
    }

    fn run(&self, req: &StageRequest, ctx: &dyn Context) -> Result<Value, StageError> {
        let resume = load_resume(req)?;
        let mut plan = plan(req, resume.as_ref())?;
        refuse_foreign_checkpoint(&plan)?;
        let resume = check_resume(&plan, resume)?;
        let mut scene = Scene::load(&req.input)?;
        scene.rebase(&req.input)?;
        // The scale comes from the initial points even when resuming, so a resumed run
        // continues with the scale it started with.
        let points = load::initial_gaussians(&scene, &req.input)?;
        if let (Some(c), Some(path)) =
            (plan.config.coc.as_mut(), req.options.get_path("focus_init"))
        {
            c.initial_focus = Some(load::known_focus(&scene, &path)?);
        }
        let views =
            load::views_scratch(&scene, req, Split::Train, plan.downscale, &plan.config, ctx)?;
        let test = (plan.eval_every > 0)
            .then(|| TestViews::load(&scene, req, plan.downscale, &plan.config, ctx))
            .transpose()?;
        let cameras: Vec<_> = views.iter().map(|v| v.camera).collect();
        let scene_scale = plan
            .schedule
            .scene_scale(&cameras, &points.means)
            .map_err(|e| StageError::Input(format!("{}: {e}", req.input.display())))?;
        plan.config.scene_scale = Some(scene_scale);
        // The addition's size follows the initial cloud (method.md §8.1), also when resuming,
        // measured in the frame the rule's constants are meant for. COLMAP's mapper normalises
        // over every registered image, the held-out ones too.
        let centres: Vec<[f64; 3]> = scene.views.iter().map(|v| v.centre()).collect();
        let unit = plan.schedule.points_frame.unit(&centres);
        let volume = crate::box_volume(&points.means) / unit.powi(3);
        let distance_given = req.options.get_f64("add_points_distance").is_some();
        for d in [&mut plan.schedule.densify]
            .into_iter()
            .chain(plan.config.densify.as_mut())
        {
            d.add_points_count =
                crate::candidate_count(volume, d.add_points_count).min(u32::MAX as usize) as u32;
            if !distance_given {
                d.add_points_distance = (f64::from(d.add_points_distance) * unit) as f32;
            }
        }
        let schedule = plan.schedule.record(scene_scale);
        let init = match &resume {
            Some(state) => state.params.clone(),
            None => points,
        };

        let gpu = GpuContext::new().map_err(StageError::other)?;
        let adapter = gpu.adapter_name();
        let (w, h) = (views[0].camera.width, views[0].camera.height);
        let start = resume.as_ref().map_or(0, |s| s.iteration);
        ctx.info(&format!(
            "training {} Gaussians on {} views ({w}×{h}), iterations {}..={} on {adapter}; \
             schedule {}, scene scale {scene_scale:.4}",
            init.len(),
            views.len(),
            start + 1,
            plan.config.iterations,
            plan.schedule.preset,
        ));
        let trainer = match &resume {
            Some(state) => Trainer::resume(&gpu, state, &views, plan.config.clone()),
            None => Trainer::new(&gpu, &init, &views, plan.config.clone()),
        }
        .map_err(|e| StageError::Input(format!("{}: {e}", req.input.display())))?;
        drop((views, init, resume));

        let start_record = json!({
            "iteration": start,
            "iterations": plan.config.iterations,
            "resume": plan.resume,
            "gaussians": trainer.num_gaussians(),
            "views": trainer.num_views(),
            "test_views": test.as_ref().map(TestViews::len),
            "downscale": plan.downscale,
            "adapter": adapter,
        });
        let mut session =
            session::Session::new(trainer, &plan, &req.output, test, &start_record, ctx)?;
        let outcome = session.run(ctx)?;
        let capped = session.trainer.growth_capped_at();
        if let Some(most) = capped {
            ctx.warn(&format!(
                "density control stopped growing the set at {most} Gaussians: {adapter} binds \
                 no larger buffer for this run (a GPU binds more; or --sh-degree lower)"
            ));
        }

        let gaussians = session.trainer.gaussians().map_err(StageError::other)?;
        let mut splats: cocog_formats::Splats = (&gaussians).into();
        finite::keep_writable(&mut splats, plan.config.iterations, ctx, |what| {
            session.diverged_error(what)
        })?;
        let ply = req.output.join("gaussians.ply");
        cocog_formats::ply::write_splats(&ply, &splats, None).map_err(StageError::other)?;
        let focus = session
            .trainer
            .focus_distances()
            .map_err(StageError::other)?;
        let train_views: Vec<usize> = (0..scene.views.len())
            .filter(|&i| scene.views[i].split == Split::Train)
            .collect();
        let apertures = session.trainer.apertures().map_err(StageError::other)?;
        for (k, (&i, &d)) in train_views.iter().zip(&focus).enumerate() {
            scene.views[i].lens = Some(cocog_pipeline::Lens {
                focus_distance: d,
                aperture: apertures.get(k).copied(),
            });
        }
        if let Some(model) = session.trainer.lens_model().map_err(StageError::other)? {
            model
                .save(&req.output.join(LENS_MODEL))
                .map_err(StageError::other)?;
            scene.lens_model = Some(LENS_MODEL.to_owned());
        }
        session.save_final(&req.output.join("checkpoint"))?;
        session.finish_log(&req.output)?;
        scene.gaussians = Some("gaussians.ply".to_owned());
        scene.save(&req.output)?;
        Ok(json!({
            "iterations": plan.config.iterations,
            "resumed_from": start,
            "checkpoint_superseded": true,
            "gaussians": splats.len(),
            "final_loss": outcome.final_loss,
            "final_psnr": outcome.final_psnr,
            "seconds": outcome.seconds,
            "it_per_s": outcome.it_per_s,
            "adapter": adapter,
            "last_psnr_drop": outcome.last_drop.map(|d| d.iteration),
            "growth_capped_at": capped,
            "test_psnr": outcome.test.as_ref().map(|t| t.psnr),
            "test_ssim": outcome.test.as_ref().and_then(|t| t.ssim),
            "method": if plan.config.coc.is_some() { "cocog" } else { "3dgs" },
            "learned_focus_distances": focus,
            "learned_apertures": apertures,
            "resolved": { "schedule": schedule, "background": plan.config.background,
                "coc": plan.config.coc.as_ref().map(|c| json!({
                "variant": c.net.variant.name(),
                "copies": c.net.copies,
                "centred": c.net.centred,
                "modulate_base": c.net.modulate_base,
                "head_init": c.head_init_scale,
                "blur_start": c.blur_start,
                "composite_start": c.composite_start,
                "compositor_channels": c.compositor_channels,
                "kernel_lr": [c.kernel_lr_init, c.kernel_lr_final],
                "refocus_every": c.refocus_every,
                "refocus_until": c.refocus_until,
            })) },
        }))
    }
}
