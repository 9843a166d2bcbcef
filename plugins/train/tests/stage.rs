//! The `train` stage end to end: synth dataset → ingest-colmap → train → files on disk.

use std::path::{Path, PathBuf};

use cocog_pipeline::{NullContext, Options, Scene, Split, Stage, StageError, StageRequest};
use serde_json::{Map, Value, json};

fn gpu_available() -> bool {
    cocog_engine::test_gpu().is_some()
}

fn stage(stages: Vec<Box<dyn Stage>>, name: &str) -> Box<dyn Stage> {
    stages
        .into_iter()
        .find(|s| s.info().name == name)
        .unwrap_or_else(|| panic!("no stage {name}"))
}

fn run(s: &dyn Stage, input: &Path, output: &Path, given: Value) -> Result<Value, StageError> {
    let info = s.info();
    let given: Map<String, Value> = given.as_object().cloned().unwrap_or_default();
    let options = Options::validate(&info.name, &info.options, &given)?;
    std::fs::create_dir_all(output).unwrap();
    let req = StageRequest {
        input: input.to_owned(),
        output: output.to_owned(),
        options,
    };
    s.run(&req, &NullContext)
}

/// A tiny synthetic dataset ingested into a scene directory.
fn ingested(root: &Path) -> PathBuf {
    let data = root.join("data");
    cocog_synth::write_defocus_dataset(&data, &cocog_synth::SynthConfig::tiny(1)).unwrap();
    let scene = root.join("scene");
    let ingest = stage(cocog_ingest::stages(), "ingest-colmap");
    run(ingest.as_ref(), &data, &scene, json!({})).unwrap();
    scene
}

#[test]
fn train_stage_writes_gaussians_log_and_scene() {
    if !gpu_available() {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let scene_dir = ingested(tmp.path());
    let before = Scene::load(&scene_dir).unwrap();
    let out = tmp.path().join("trained");
    let train = stage(cocog_train::stages(), "train");
    let summary = run(
        train.as_ref(),
        &scene_dir,
        &out,
        json!({"method": "3dgs", "iterations": 150, "downscale": 1, "seed": 3}),
    )
    .unwrap();
    eprintln!("summary: {summary}");

    let splats = cocog_formats::ply::read_splats(&out.join("gaussians.ply")).unwrap();
    let count = splats.opacities.len() as u64;
    assert!(count > 0);
    assert_eq!(Some(count), summary["gaussians"].as_u64());
    assert_eq!(summary["iterations"], 150);
    // The schedule is resolved in full for the history: preset, derived scale, constants.
    let schedule = &summary["resolved"]["schedule"];
    assert_eq!(schedule["preset"], "auto", "{schedule}");
    assert!(
        schedule["scene_scale"].as_f64().unwrap() > 0.0,
        "{schedule}"
    );
    assert_eq!(schedule["opacity_reset_every"], 3000, "{schedule}");
    assert!(summary["it_per_s"].as_f64().unwrap() > 0.0);

    let log = std::fs::read_to_string(out.join("train-log.jsonl")).unwrap();
    let mut lines: Vec<Value> = log
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    // The first line says what the run starts from; the last sums it up, collapse
    // detection included.
    let start = lines.remove(0);
    assert_eq!(start["start"]["iteration"], 0, "{start}");
    assert_eq!(start["start"]["iterations"], 150, "{start}");
    let end = lines.pop().unwrap();
    assert_eq!(end["summary"]["iterations"], 150, "{end}");
    assert!(end["summary"].get("last_psnr_drop").is_some(), "{end}");
    assert_eq!(end["summary"]["last_psnr_drop"], summary["last_psnr_drop"]);
    assert!(lines.len() >= 2, "log has {} lines", lines.len());
    let losses: Vec<f64> = lines.iter().map(|l| l["loss"].as_f64().unwrap()).collect();
    eprintln!("logged losses: {losses:.4?}");
    assert!(losses.iter().all(|l| l.is_finite()), "{losses:?}");
    assert!(
        losses.last() < losses.first(),
        "loss did not fall: {losses:?}"
    );
    for key in ["iteration", "psnr", "gaussians", "elapsed_s", "it_per_s"] {
        assert!(lines[0].get(key).is_some(), "log line lacks {key}");
    }
    // serde_json's default float parser may be 1 ulp off, so compare with a tolerance.
    let final_loss = summary["final_loss"].as_f64().unwrap();
    assert!(
        (final_loss - losses[losses.len() - 1]).abs() < 1e-12,
        "{final_loss} vs {losses:?}"
    );

    let after = Scene::load(&out).unwrap();
    assert_eq!(after.gaussians.as_deref(), Some("gaussians.ply"));
    assert_eq!(after.history, before.history);
    assert_eq!(after.views.len(), before.views.len());
    // The points stay with the input scene, referenced by an absolute path.
    let points = PathBuf::from(after.points.unwrap());
    assert!(points.is_absolute() && points.exists(), "{points:?}");

    assert_eq!(summary["resolved"]["background"], json!([0.0, 0.0, 0.0]));

    // Photos with alpha are composited over the chosen background (white here), which the
    // history records; an unknown colour is refused naming the option.
    let white = tmp.path().join("white");
    let summary = run(
        train.as_ref(),
        &scene_dir,
        &white,
        json!({"iterations": 5, "downscale": 2, "sh_degree": 0, "background": "white"}),
    )
    .unwrap();
    assert_eq!(summary["resolved"]["background"], json!([1.0, 1.0, 1.0]));
    let err = run(
        train.as_ref(),
        &scene_dir,
        &tmp.path().join("grey"),
        json!({"background": "grey"}),
    )
    .unwrap_err();
    assert!(matches!(err, StageError::Options(_)), "{err:?}");
    assert!(err.to_string().contains("'background'"), "{err}");

    // Half resolution trains too, and its scratch PNGs do not end up in the output.
    let half = tmp.path().join("half");
    let summary = run(
        train.as_ref(),
        &scene_dir,
        &half,
        json!({"iterations": 20, "downscale": 2, "sh_degree": 0}),
    )
    .unwrap();
    assert!(summary["gaussians"].as_u64().unwrap() > 0);
    assert!(half.join("gaussians.ply").exists());
    assert!(!half.join(".downscaled").exists());
}

/// A resumed run without `method` keeps its checkpoint's method, and a cocog run keeps the
/// starts it was fitted to even when the resume asks for more iterations.
#[test]
fn a_resume_keeps_the_checkpoints_method_and_starts() {
    if !gpu_available() {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let scene_dir = ingested(tmp.path());
    let train = stage(cocog_train::stages(), "train");
    let small = json!({"downscale": 2, "sh_degree": 0, "compositor_channels": 4});
    let with = |extra: Value| {
        let mut o = small.clone();
        o.as_object_mut()
            .unwrap()
            .extend(extra.as_object().unwrap().clone());
        o
    };
    let plain = tmp.path().join("plain");
    let opts = with(json!({"method": "3dgs", "iterations": 6}));
    run(train.as_ref(), &scene_dir, &plain, opts).unwrap();
    let more = with(json!({"iterations": 8, "resume": plain.display().to_string()}));
    let summary = run(train.as_ref(), &scene_dir, &tmp.path().join("p2"), more).unwrap();
    assert_eq!(summary["method"], "3dgs", "{summary}");
    assert_eq!(summary["resolved"]["schedule"]["preset"], "auto");

    let coc = tmp.path().join("coc");
    run(
        train.as_ref(),
        &scene_dir,
        &coc,
        with(json!({"iterations": 14})),
    )
    .unwrap();
    let more = with(json!({"iterations": 70, "resume": coc.display().to_string()}));
    let summary = run(train.as_ref(), &scene_dir, &tmp.path().join("c2"), more).unwrap();
    assert_eq!(summary["method"], "cocog", "{summary}");
    let resolved = &summary["resolved"]["coc"];
    // Fitted to 14 iterations (2000 and 6000 of 7000), not to the 70 asked for now.
    assert_eq!(resolved["blur_start"], 4, "{resolved}");
    assert_eq!(resolved["composite_start"], 12, "{resolved}");
    assert_eq!(resolved["variant"], "paper", "{resolved}");
}

/// With no method named the stage trains CoCoGaussian's paper variant, and a run shorter than
/// the 7000 iterations its starts were measured with blurs and composites at the same shares.
#[test]
fn the_default_is_cocog_with_its_starts_fitted_to_the_run() {
    if !gpu_available() {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let scene_dir = ingested(tmp.path());
    let train = stage(cocog_train::stages(), "train");
    let out = tmp.path().join("t");
    let options = json!({"iterations": 7, "downscale": 2, "sh_degree": 0,
        "compositor_channels": 4});
    let summary = run(train.as_ref(), &scene_dir, &out, options).unwrap();
    assert_eq!(summary["method"], "cocog", "{summary}");
    let coc = &summary["resolved"]["coc"];
    assert_eq!(coc["variant"], "paper", "{coc}");
    // 2000 and 6000 of 7000, at 7 iterations.
    assert_eq!(
        (&coc["blur_start"], &coc["composite_start"]),
        (&json!(2), &json!(6))
    );
    assert_eq!(summary["resolved"]["schedule"]["preset"], "deblur");
    let scene = Scene::load(&out).unwrap();
    assert!(scene.lens_model.is_some());
    assert!(
        scene
            .views
            .iter()
            .filter(|v| v.split == Split::Train)
            .all(|v| v.lens.as_ref().is_some_and(|l| l.focus_distance > 0.0))
    );
}

/// In COLMAP's frame the point addition's volume and distance follow the camera centres'
/// robust box; in the scene's own units they are the formula's numbers as they stand.
#[test]
fn the_point_addition_reads_its_constants_in_the_frame_asked_for() {
    if !gpu_available() {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let scene_dir = ingested(tmp.path());
    let scene = Scene::load(&scene_dir).unwrap();
    // Every view, as COLMAP's mapper normalises over every registered image.
    let centres: Vec<[f64; 3]> = scene
        .views
        .iter()
        .map(|v| {
            let m = v.world_from_camera;
            [m[0][3], m[1][3], m[2][3]]
        })
        .collect();
    let unit = cocog_train::colmap_unit(&centres).unwrap();
    let cloud = cocog_formats::ply::read_points(&scene_dir.join("points.ply")).unwrap();
    let means: Vec<[f32; 3]> = cloud
        .positions
        .chunks_exact(3)
        .map(|p| [p[0], p[1], p[2]])
        .collect();
    let volume = cocog_train::box_volume(&means);
    let train = stage(cocog_train::stages(), "train");
    for (frame, length) in [("scene", 1.0), ("colmap", unit)] {
        let out = tmp.path().join(frame);
        let options = json!({"iterations": 2, "downscale": 2, "sh_degree": 0, "method": "3dgs",
            "schedule": "deblur", "add_points_frame": frame});
        let summary = run(train.as_ref(), &scene_dir, &out, options).unwrap();
        let s = &summary["resolved"]["schedule"];
        assert_eq!(s["add_points_frame"], frame, "{s}");
        let want = cocog_train::candidate_count(volume / length.powi(3), 200_000);
        assert_eq!(s["add_points_count"], want, "{frame}: {s}");
        let distance = s["add_points_distance"].as_f64().unwrap();
        assert!(
            (distance - 2.0 * length).abs() < 1e-6 * length,
            "{frame}: {s}"
        );
    }
}

#[test]
fn cocog_method_and_missing_points_are_clear_errors() {
    let tmp = tempfile::tempdir().unwrap();
    let train = stage(cocog_train::stages(), "train");
    let err = run(
        train.as_ref(),
        tmp.path(),
        &tmp.path().join("o1"),
        json!({"method": "cocog", "coc_variant": "pinhole"}),
    )
    .unwrap_err();
    assert!(matches!(err, StageError::Options(_)));
    // Refused by the option table's choices, before the stage starts.
    assert!(
        err.to_string()
            .contains("'coc_variant': expected paper, lens or code, got \"pinhole\""),
        "{err}"
    );
    let err = run(
        train.as_ref(),
        tmp.path(),
        &tmp.path().join("o1"),
        json!({"method": "cocog", "refocus_every": -250}),
    )
    .unwrap_err();
    assert!(matches!(err, StageError::Options(_)));
    assert!(err.to_string().contains("'refocus_every'"), "{err}");

    let scene_dir = ingested(tmp.path());
    let mut scene = Scene::load(&scene_dir).unwrap();
    scene.points = None;
    scene.save(&scene_dir).unwrap();
    let err = run(
        train.as_ref(),
        &scene_dir,
        &tmp.path().join("o2"),
        json!({}),
    )
    .unwrap_err();
    assert!(matches!(err, StageError::Input(_)), "{err:?}");
    assert!(err.to_string().contains("`points`"), "{err}");
}

/// Cancels once training progress reaches `at`, like a Ctrl-C mid-run.
struct CancelAt {
    at: u64,
    reached: std::sync::atomic::AtomicBool,
}

impl cocog_pipeline::Context for CancelAt {
    fn log(&self, _: cocog_pipeline::LogLevel, message: &str) {
        eprintln!("{message}");
    }

    fn progress(&self, task: &str, done: u64, _: u64) {
        if task == "train" && done >= self.at {
            self.reached
                .store(true, std::sync::atomic::Ordering::Relaxed);
        }
    }

    fn cancelled(&self) -> bool {
        self.reached.load(std::sync::atomic::Ordering::Relaxed)
    }
}

#[test]
fn an_interrupted_run_leaves_a_checkpoint_that_resumes_to_the_end() {
    if !gpu_available() {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let scene_dir = ingested(tmp.path());
    let train = stage(cocog_train::stages(), "train");
    let ckpt = tmp.path().join("run.checkpoint");
    // CoCoGaussian on purpose (h_θ from 17, F from 51 of 60): its lens model must resume too.
    let options = json!({
        "method": "cocog", "compositor_channels": 8,
        "iterations": 60, "seed": 2, "sh_degree": 1, "random_background": true,
        "checkpoint_dir": ckpt.display().to_string(), "checkpoint_every": 0,
    });
    let given = options.as_object().cloned().unwrap();
    let opts = Options::validate("train", &train.info().options, &given).unwrap();
    let out = tmp.path().join("run");
    std::fs::create_dir_all(&out).unwrap();
    let req = StageRequest {
        input: scene_dir.clone(),
        output: out,
        options: opts,
    };
    let ctx = CancelAt {
        at: 30,
        reached: Default::default(),
    };
    let err = train.run(&req, &ctx).unwrap_err();
    assert!(matches!(err, StageError::Cancelled), "{err:?}");
    let saved = cocog_train::TrainState::load(&ckpt).unwrap();
    assert_eq!(saved.iteration, 30);

    // A fresh run that would keep its checkpoint there refuses, and the checkpoint survives.
    let err = run(
        train.as_ref(),
        &scene_dir,
        &tmp.path().join("fresh"),
        options.clone(),
    )
    .unwrap_err()
    .to_string();
    assert!(
        err.contains("--resume") && err.contains("interrupted"),
        "{err}"
    );
    assert_eq!(cocog_train::TrainState::load(&ckpt).unwrap().iteration, 30);

    let mut resumed = options.clone();
    resumed["resume"] = json!(ckpt.display().to_string());
    let done = tmp.path().join("done");
    let summary = run(train.as_ref(), &scene_dir, &done, resumed).unwrap();
    assert_eq!(summary["resumed_from"], 30);
    assert_eq!(summary["iterations"], 60);
    // The runner removes the in-progress checkpoint once the output is in place.
    assert_eq!(summary["checkpoint_superseded"], true);
    assert!(
        ckpt.exists(),
        "the stage itself never deletes the checkpoint"
    );
    std::fs::remove_dir_all(&ckpt).unwrap();
    let last = cocog_train::TrainState::load(&done).unwrap();
    assert_eq!(last.iteration, 60);
    let splats = cocog_formats::ply::read_splats(&done.join("gaussians.ply")).unwrap();
    assert_eq!(splats.opacities.len(), last.params.len());

    // A different image size or a finished run cannot be continued.
    for (key, value, expect) in [
        ("downscale", json!(2), "downscale"),
        ("iterations", json!(60), "already at iteration 60"),
    ] {
        let mut o = options.clone();
        o["resume"] = json!(done.display().to_string());
        o[key] = value;
        let err = run(train.as_ref(), &scene_dir, &tmp.path().join("x"), o).unwrap_err();
        assert!(err.to_string().contains(expect), "{err}");
    }
}

/// Records every log line and progress report, like a terminal would show them.
#[derive(Default)]
struct Recorder(std::sync::Mutex<Vec<String>>);

impl cocog_pipeline::Context for Recorder {
    fn log(&self, _: cocog_pipeline::LogLevel, message: &str) {
        self.0.lock().unwrap().push(message.to_owned());
    }

    fn progress(&self, task: &str, done: u64, _: u64) {
        self.0
            .lock()
            .unwrap()
            .push(format!("progress {task} {done}"));
    }

    fn cancelled(&self) -> bool {
        false
    }
}

#[test]
fn the_live_log_is_told_and_the_test_views_are_scored_into_it() {
    if !gpu_available() {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let scene_dir = ingested(tmp.path());
    let train = stage(cocog_train::stages(), "train");
    let live = tmp.path().join("run.train-log.jsonl");
    let given = json!({
        "method": "3dgs", "iterations": 50, "eval_every": 20, "seed": 4,
        "live_log": live.display().to_string(),
    });
    let opts = Options::validate("train", &train.info().options, given.as_object().unwrap());
    let out = tmp.path().join("staging");
    std::fs::create_dir_all(&out).unwrap();
    let req = StageRequest {
        input: scene_dir.clone(),
        output: out.clone(),
        options: opts.unwrap(),
    };
    let ctx = Recorder::default();
    let summary = train.run(&req, &ctx).unwrap();
    let said = ctx.0.into_inner().unwrap();
    assert!(
        said.iter()
            .any(|l| l.contains("training log") && l.contains(&*live.to_string_lossy())),
        "{said:?}"
    );
    // Progress comes every step, so a host can pace its lines by time, after one report of
    // where the run starts (its rates count from there).
    let steps: Vec<&String> = said
        .iter()
        .filter(|l| l.starts_with("progress train "))
        .collect();
    assert_eq!(steps.len(), 51, "{said:?}");
    assert_eq!(steps[0], "progress train 0");

    // The live log was written beside the output and copied into it whole.
    let log = std::fs::read_to_string(&live).unwrap();
    assert_eq!(
        log,
        std::fs::read_to_string(out.join("train-log.jsonl")).unwrap()
    );
    let records: Vec<Value> = log
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let evals: Vec<&Value> = records.iter().filter_map(|r| r.get("eval")).collect();
    let at: Vec<u64> = evals
        .iter()
        .map(|e| e["iteration"].as_u64().unwrap())
        .collect();
    assert_eq!(at, [20, 40, 50], "every 20 iterations and at the end");
    for e in &evals {
        assert_eq!(e["split"], "test");
        assert!(e["views"].as_u64().unwrap() > 0, "{e}");
        let (psnr, ssim) = (e["psnr"].as_f64().unwrap(), e["ssim"].as_f64().unwrap());
        assert!(psnr.is_finite() && psnr > 5.0, "{e}");
        assert!((-1.0..=1.0).contains(&ssim), "{e}");
    }
    // serde_json's default float parser may be 1 ulp off, so compare with a tolerance.
    let last = evals[2]["psnr"].as_f64().unwrap();
    let summed = records.last().unwrap()["summary"]["test_psnr"].as_f64();
    for v in [summary["test_psnr"].as_f64(), summed] {
        assert!((v.unwrap() - last).abs() < 1e-9, "{v:?} vs {last}");
    }
    assert!(
        said.iter()
            .any(|l| l.starts_with("iteration 40: test views PSNR")),
        "{said:?}"
    );

    // A scene without test views cannot be scored: said before training starts.
    let mut scene = Scene::load(&scene_dir).unwrap();
    for v in &mut scene.views {
        v.split = cocog_pipeline::Split::Train;
    }
    scene.save(&scene_dir).unwrap();
    let err = run(
        train.as_ref(),
        &scene_dir,
        &tmp.path().join("none"),
        json!({"iterations": 10, "eval_every": 5}),
    )
    .unwrap_err();
    assert!(err.to_string().contains("no test views"), "{err}");
}

/// `focus_init` seeds every photo's focus distance from a transforms.json (matched by file
/// name), and one photo without a focus there is an error that names it.
#[test]
fn known_focus_distances_seed_the_lens_and_gaps_are_named() {
    if !gpu_available() {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let scene_dir = ingested(tmp.path());
    let transforms = tmp.path().join("data/transforms.json");
    let doc: Value = serde_json::from_str(&std::fs::read_to_string(&transforms).unwrap()).unwrap();
    let truth: std::collections::HashMap<String, f64> = doc["frames"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|f| {
            let name = Path::new(f["file_path"].as_str()?).file_name()?;
            Some((
                name.to_string_lossy().into_owned(),
                f["focus_distance_m"].as_f64()?,
            ))
        })
        .collect();
    let train = stage(cocog_train::stages(), "train");
    // The lens starts at the blur start and barely learns in 3 steps at this rate.
    let options = json!({"method": "cocog", "iterations": 3, "blur_start": 1,
        "coc_head_init": 0.0, "kernel_lr": 1e-9, "focus_init": transforms});
    let out = tmp.path().join("t");
    run(train.as_ref(), &scene_dir, &out, options.clone()).unwrap();
    let scene = Scene::load(&out).unwrap();
    let mut seen = 0;
    for v in scene.views.iter().filter(|v| v.split == Split::Train) {
        let learned = v.lens.as_ref().unwrap().focus_distance;
        let known = truth[&v.name];
        assert!(
            (learned - known).abs() <= 1e-5 * known,
            "{}: {learned} vs {known}",
            v.name
        );
        seen += 1;
    }
    assert!(seen >= 2, "{seen} training views");

    // Without it the focus starts elsewhere: the option is what put it there.
    let plain = tmp.path().join("p");
    let mut without = options.as_object().unwrap().clone();
    without.remove("focus_init");
    run(train.as_ref(), &scene_dir, &plain, Value::Object(without)).unwrap();
    let scene = Scene::load(&plain).unwrap();
    let differs = scene
        .views
        .iter()
        .filter(|v| v.split == Split::Train)
        .any(|v| (v.lens.as_ref().unwrap().focus_distance - truth[&v.name]).abs() > 1e-3);
    assert!(differs);

    let mut gap = doc;
    let first_train = gap["frames"]
        .as_array_mut()
        .unwrap()
        .iter_mut()
        .find(|f| f["focus_distance_m"].is_number())
        .unwrap();
    first_train["focus_distance_m"] = Value::Null;
    let named = Path::new(first_train["file_path"].as_str().unwrap())
        .file_name()
        .unwrap()
        .to_string_lossy()
        .into_owned();
    let gappy = tmp.path().join("gappy.json");
    std::fs::write(&gappy, serde_json::to_string(&gap).unwrap()).unwrap();
    let mut with_gap = options.as_object().unwrap().clone();
    with_gap.insert("focus_init".into(), json!(gappy));
    let err = run(
        train.as_ref(),
        &scene_dir,
        &tmp.path().join("g"),
        Value::Object(with_gap),
    )
    .unwrap_err();
    assert!(matches!(err, StageError::Input(_)), "{err:?}");
    let said = err.to_string();
    assert!(
        said.contains("gappy.json") && said.contains(&named),
        "{said}"
    );
}

/// `focus_estimate`: at the blur start each photo's focus comes from depth from defocus
/// against the warm-up Gaussians (the estimator itself is checked against an f64 thin-lens
/// photograph in `focus_estimate.rs`): it replaces the mean-distance start and stays within
/// the depths the scene spans. On this 48×36 scene after 300 iterations it is not nearer the
/// truth than the mean distance (BENCHMARKS.md has the figures at real sizes).
#[test]
fn estimated_focus_replaces_the_mean_distance_start() {
    if !gpu_available() {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let scene_dir = ingested(tmp.path());
    let train = stage(cocog_train::stages(), "train");
    // 300 warm-up iterations of plain 3DGS, then the lens starts and (at this rate) stays.
    let options = json!({"method": "cocog", "iterations": 301, "blur_start": 301,
        "coc_head_init": 0.0, "kernel_lr": 1e-9, "seed": 5});
    let mean = tmp.path().join("mean");
    run(train.as_ref(), &scene_dir, &mean, options.clone()).unwrap();
    let mut with = options.as_object().unwrap().clone();
    with.insert("focus_estimate".into(), json!(true));
    let estimated = tmp.path().join("estimated");
    let summary = run(train.as_ref(), &scene_dir, &estimated, Value::Object(with)).unwrap();
    // Refocusing is off unless asked for; its last iteration resolves to the end of the run.
    let coc = &summary["resolved"]["coc"];
    assert_eq!(
        (&coc["refocus_every"], &coc["refocus_until"]),
        (&json!(0), &json!(301))
    );
    let focus = |dir: &Path| -> Vec<f64> {
        let scene = Scene::load(dir).unwrap();
        scene
            .views
            .iter()
            .filter(|v| v.split == Split::Train)
            .map(|v| v.lens.as_ref().unwrap().focus_distance)
            .collect()
    };
    let (from_mean, from_estimate) = (focus(&mean), focus(&estimated));
    eprintln!("focus: mean-distance start {from_mean:?}, estimated {from_estimate:?}");
    let bounds = Scene::load(&scene_dir).unwrap().bounds.unwrap();
    let moved = from_mean
        .iter()
        .zip(&from_estimate)
        .filter(|(m, e)| (*m - *e).abs() > 0.02 * *m)
        .count();
    assert!(
        2 * moved > from_mean.len(),
        "{moved} of {} moved",
        from_mean.len()
    );
    for d in from_estimate {
        assert!(
            d >= 0.9 * bounds.near && d <= 1.1 * bounds.far,
            "{d} outside {bounds:?}"
        );
    }
}

#[test]
fn a_run_whose_gaussians_leave_f32s_range_stops_and_writes_nothing() {
    if !gpu_available() {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let scene_dir = ingested(tmp.path());
    let out = tmp.path().join("trained");
    let train = stage(cocog_train::stages(), "train");
    // A run that diverges, with `extra` options: its error.
    let diverging = |extra: serde_json::Value| {
        let mut options = json!({"method": "3dgs", "iterations": 60, "downscale": 1, "seed": 3,
                                 "position_lr": 1.0, "scene_scale": "3e38"});
        let fields = options.as_object_mut().unwrap();
        fields.extend(extra.as_object().unwrap().clone());
        run(train.as_ref(), &scene_dir, &out, options)
            .unwrap_err()
            .to_string()
    };
    let err = diverging(json!({}));
    // Every Gaussian flies past f32's range in the first steps and leaves every render: the
    // loss stays a number (the background's), the parameters do not.
    assert!(
        err.contains("training diverged: after iteration 60,")
            && err.contains(
                "Gaussians hold NaN or infinite values or an all-zero rotation (the first: \
                 Gaussian 0); nothing was written"
            ),
        "{err}"
    );
    assert!(!out.join("gaussians.ply").exists());

    // A checkpoint kept beside the output stays, and the error says so: it may already hold
    // the values that broke the run.
    let checkpoint = tmp.path().join("trained.checkpoint");
    let err = diverging(json!({"checkpoint_dir": checkpoint, "checkpoint_every": 25}));
    let kept = format!(
        "the output was not written, but the checkpoint {} (saved at iteration 50; it may \
         already hold the bad values) remains (remove it to start afresh)",
        checkpoint.display()
    );
    assert!(err.contains(&kept), "{err}");
    assert!(checkpoint.is_dir() && !out.join("gaussians.ply").exists());

    // Resumed from it, with a live log: both are named, the checkpoint as the run's start.
    let log = tmp.path().join("trained.train-log.jsonl");
    let err = diverging(json!({"resume": checkpoint, "checkpoint_dir": checkpoint,
                               "checkpoint_every": 25, "live_log": log}));
    let kept = format!(
        "but the checkpoint {} (the one this run started from) and the log {} remain (remove \
         them to start afresh)",
        checkpoint.display(),
        log.display()
    );
    assert!(err.contains(&kept), "{err}");
}
