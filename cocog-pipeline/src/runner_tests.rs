//! The runner's history entry (options as validated, and what the stage resolved), and the
//! checkpoint and live log it removes once a stage's output supersedes them.

use std::path::Path;
use std::sync::Arc;

use serde_json::{Map, Value, json};

use crate::registry::{Provider, StageEntry};
use crate::runner::{RunHow, run_stage, run_stage_with};
use crate::stage::{OutputKind, StageInfo, StageKind};
use crate::testing::one_view_scene;
use crate::{Context, NullContext, OptionSpec, Scene, Stage, StageError, StageRequest};

/// Copies the scene and reports a `resolved` object, as train does with its schedule.
struct Resolving;

impl Stage for Resolving {
    fn info(&self) -> StageInfo {
        StageInfo {
            name: "resolving".into(),
            kind: StageKind::Transform,
            output: OutputKind::Dir,
            needs_gaussians: false,
            description: "test stage".into(),
            options: vec![OptionSpec::int("k", 3, "a constant")],
        }
    }

    fn run(&self, req: &StageRequest, _ctx: &dyn Context) -> Result<Value, StageError> {
        Scene::load(&req.input)?.save(&req.output)?;
        Ok(json!({ "resolved": { "k_times_two": 2 * req.options.get_i64("k").unwrap_or(0) } }))
    }
}

fn entry() -> StageEntry {
    built_in(Arc::new(Resolving))
}

fn built_in(stage: Arc<dyn Stage>) -> StageEntry {
    StageEntry {
        info: stage.info(),
        stage,
        provider: Provider::BuiltIn,
    }
}

fn run(input: &Path, output: &Path, given: Value) -> Scene {
    let given: Map<String, Value> = serde_json::from_value(given).unwrap();
    run_stage(&entry(), input, output, &given, false, &NullContext).unwrap();
    Scene::load(output).unwrap()
}

#[test]
fn history_records_the_options_and_what_the_stage_resolved() {
    let tmp = tempfile::tempdir().unwrap();
    let input = tmp.path().join("in");
    std::fs::create_dir(&input).unwrap();
    one_view_scene().save(&input).unwrap();
    let out = run(&input, &tmp.path().join("out"), json!({"k": 5}));
    let entry = out.history.last().unwrap();
    assert_eq!(entry.stage, "resolving");
    assert_eq!(entry.options, json!({"k": 5}));
    assert_eq!(entry.resolved, Some(json!({"k_times_two": 10})));
    // Defaults are recorded too, and a scene without `resolved` in its history still loads.
    let again = run(
        &tmp.path().join("out"),
        &tmp.path().join("again"),
        json!({}),
    );
    assert_eq!(again.history[1].options, json!({"k": 3}));
    let text = std::fs::read_to_string(tmp.path().join("again/scene.json")).unwrap();
    let mut raw: Value = serde_json::from_str(&text).unwrap();
    raw["history"][0]
        .as_object_mut()
        .unwrap()
        .remove("resolved");
    std::fs::write(tmp.path().join("again/scene.json"), raw.to_string()).unwrap();
    let old = Scene::load(&tmp.path().join("again")).unwrap();
    assert_eq!(old.history[0].resolved, None);
}

/// Leaves its checkpoint directory and live log alone and says whether its output supersedes
/// them.
struct Checkpointing;

impl Stage for Checkpointing {
    fn info(&self) -> StageInfo {
        StageInfo {
            name: "checkpointing".into(),
            kind: StageKind::Train,
            output: OutputKind::Dir,
            needs_gaussians: false,
            description: "test stage".into(),
            options: vec![
                OptionSpec::optional("checkpoint_dir", crate::OptionKind::Path, "where"),
                OptionSpec::optional("live_log", crate::OptionKind::Path, "where"),
                OptionSpec::bool("done", true, "whether the output supersedes it"),
            ],
        }
    }

    fn run(&self, req: &StageRequest, _ctx: &dyn Context) -> Result<Value, StageError> {
        Scene::load(&req.input)?.save(&req.output)?;
        Ok(json!({ "checkpoint_superseded": req.options.get_bool("done") }))
    }
}

#[test]
fn a_superseded_checkpoint_and_log_are_removed_after_the_commit_and_only_then() {
    let tmp = tempfile::tempdir().unwrap();
    let input = tmp.path().join("in");
    std::fs::create_dir(&input).unwrap();
    one_view_scene().save(&input).unwrap();
    let entry = built_in(Arc::new(Checkpointing));
    let ckpt = tmp.path().join("out.checkpoint");
    let log = tmp.path().join("out.train-log.jsonl");
    for (done, kept) in [(false, true), (true, false)] {
        std::fs::create_dir_all(&ckpt).unwrap();
        std::fs::write(ckpt.join("state.safetensors"), b"x").unwrap();
        std::fs::write(&log, b"{}\n").unwrap();
        let given: Map<String, Value> = serde_json::from_value(json!({
            "checkpoint_dir": ckpt.display().to_string(), "done": done,
            "live_log": log.display().to_string(),
        }))
        .unwrap();
        let out = tmp.path().join("out");
        run_stage(&entry, &input, &out, &given, true, &NullContext).unwrap();
        assert!(out.join("scene.json").exists());
        assert_eq!(ckpt.exists(), kept, "superseded: {done}");
        assert_eq!(log.exists(), kept, "superseded: {done}");
    }
}

/// Writes its input scene with every reference made absolute, as real stages do, and a file
/// of its own named like the input's Gaussians.
struct Rebasing;

impl Stage for Rebasing {
    fn info(&self) -> StageInfo {
        StageInfo {
            name: "rebasing".into(),
            kind: StageKind::Transform,
            output: OutputKind::Dir,
            needs_gaussians: false,
            description: "test stage".into(),
            options: vec![],
        }
    }

    fn run(&self, req: &StageRequest, _ctx: &dyn Context) -> Result<Value, StageError> {
        let mut scene = Scene::load(&req.input)?;
        scene.rebase(&req.input)?;
        std::fs::write(req.output.join("gaussians.ply"), b"own").unwrap();
        scene.save(&req.output)?;
        Ok(json!({}))
    }
}

#[test]
fn a_scene_output_carries_its_model_files_and_outlives_its_input() {
    let tmp = tempfile::tempdir().unwrap();
    let input = tmp.path().join("in");
    std::fs::create_dir(&input).unwrap();
    let mut scene = one_view_scene();
    scene.points = Some("points.ply".into());
    scene.gaussians = Some("gaussians.ply".into());
    scene.lens_model = Some("lens-model.safetensors".into());
    scene.save(&input).unwrap();
    for (file, text) in [
        ("points.ply", "points"),
        ("gaussians.ply", "upstream"),
        ("lens-model.safetensors", "lens"),
        ("a.png", "photo"),
    ] {
        std::fs::write(input.join(file), text).unwrap();
    }
    let entry = built_in(Arc::new(Rebasing));
    let out = tmp.path().join("out");
    run_stage(&entry, &input, &out, &Map::new(), false, &NullContext).unwrap();
    // The model files are copied and referenced relatively; the stage's own file is kept and
    // the input's of the same name gets another; photos stay where they are.
    std::fs::remove_file(input.join("points.ply")).unwrap();
    std::fs::remove_file(input.join("gaussians.ply")).unwrap();
    std::fs::remove_file(input.join("lens-model.safetensors")).unwrap();
    let s = Scene::load(&out).unwrap();
    let read = |stored: &Option<String>| {
        let stored = stored.as_deref().unwrap();
        assert!(!Path::new(stored).is_absolute(), "{stored}");
        std::fs::read_to_string(Scene::resolve(&out, stored)).unwrap()
    };
    assert_eq!(read(&s.points), "points");
    assert_eq!(read(&s.gaussians), "upstream");
    assert_eq!(read(&s.lens_model), "lens");
    assert_eq!(
        std::fs::read_to_string(out.join("gaussians.ply")).unwrap(),
        "own"
    );
    assert!(Path::new(&s.views[0].image).is_absolute());
    assert_eq!(std::fs::read_to_string(&s.views[0].image).unwrap(), "photo");
}

#[test]
fn copy_images_makes_a_scene_self_contained() {
    let tmp = tempfile::tempdir().unwrap();
    let (input, other) = (tmp.path().join("in"), tmp.path().join("other"));
    std::fs::create_dir(&input).unwrap();
    std::fs::create_dir(&other).unwrap();
    // Two views whose photos share a file name in different folders, one with depth, one
    // photo used twice.
    let mut scene = one_view_scene();
    let mut b = scene.views[0].clone();
    b.name = "b".into();
    b.image = other.join("a.png").display().to_string();
    b.depth = Some("d.exr".into());
    let mut c = scene.views[0].clone();
    c.name = "c".into();
    scene.views.extend([b, c]);
    scene.save(&input).unwrap();
    std::fs::write(input.join("a.png"), "photo a").unwrap();
    std::fs::write(other.join("a.png"), "photo b").unwrap();
    std::fs::write(input.join("d.exr"), "depth b").unwrap();
    let entry = built_in(Arc::new(Rebasing));
    let out = tmp.path().join("out");
    let how = RunHow {
        copy_images: true,
        ..RunHow::default()
    };
    run_stage_with(&entry, &input, &out, &Map::new(), &how, &NullContext).unwrap();
    std::fs::remove_dir_all(&input).unwrap();
    std::fs::remove_dir_all(&other).unwrap();
    let s = Scene::load(&out).unwrap();
    let read = |stored: &str| {
        assert!(!Path::new(stored).is_absolute(), "{stored}");
        std::fs::read_to_string(out.join(stored)).unwrap()
    };
    assert_eq!(read(&s.views[0].image), "photo a");
    assert_eq!(read(&s.views[1].image), "photo b");
    assert_eq!(read(s.views[1].depth.as_deref().unwrap()), "depth b");
    assert_eq!(s.views[2].image, s.views[0].image, "one copy per photo");
    assert_ne!(s.views[0].image, s.views[1].image);
    assert!(
        s.views[0].image.starts_with("images/"),
        "{}",
        s.views[0].image
    );
}
