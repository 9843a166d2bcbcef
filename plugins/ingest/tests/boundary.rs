//! Ingest on tiny synthetic datasets: image paths that leave the dataset folder, downscale
//! factors larger than the images, and a `hold=0` marker (no test views) are caught up front.

use std::path::Path;
use std::sync::Mutex;

use cocog_formats::colmap::{self, Camera, CameraModel, Image, Model};
use cocog_pipeline::{Context, LogLevel, Options, StageError, StageRequest};
use serde_json::{Value, json};

#[derive(Default)]
struct Recorder(Mutex<Vec<(LogLevel, String)>>);

impl Context for Recorder {
    fn log(&self, level: LogLevel, message: &str) {
        self.0.lock().unwrap().push((level, message.to_owned()));
    }
    fn progress(&self, _task: &str, _done: u64, _total: u64) {}
    fn cancelled(&self) -> bool {
        false
    }
}

fn run(stage: &str, input: &Path, options: Value, ctx: &Recorder) -> Result<Value, StageError> {
    let stage = cocog_ingest::stages()
        .into_iter()
        .find(|s| s.info().name == stage)
        .unwrap();
    let info = stage.info();
    let options = Options::validate(&info.name, &info.options, options.as_object().unwrap())?;
    let out = tempfile::tempdir().unwrap();
    stage.run(
        &StageRequest {
            input: input.to_path_buf(),
            output: out.path().to_path_buf(),
            options,
        },
        ctx,
    )
}

fn err(stage: &str, input: &Path, options: Value) -> String {
    run(stage, input, options, &Recorder::default())
        .unwrap_err()
        .to_string()
}

fn png(path: &Path) {
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    image::RgbImage::new(8, 6).save(path).unwrap();
}

fn pose(z: f64) -> [[f64; 4]; 4] {
    [
        [1.0, 0.0, 0.0, 0.0],
        [0.0, 1.0, 0.0, 0.0],
        [0.0, 0.0, 1.0, z],
        [0.0, 0.0, 0.0, 1.0],
    ]
}

/// `<tmp>/scene` with transforms.json listing `paths` (8×6 images, created where they point).
fn nerf_scene(paths: &[&str]) -> tempfile::TempDir {
    let tmp = tempfile::tempdir().unwrap();
    let scene = tmp.path().join("scene");
    let frames: Vec<Value> = paths
        .iter()
        .enumerate()
        .map(|(i, p)| {
            png(&scene.join(p));
            json!({"file_path": p, "transform_matrix": pose(4.0 + i as f64)})
        })
        .collect();
    let doc = json!({"fl_x": 10.0, "w": 8, "h": 6, "frames": frames});
    std::fs::write(scene.join("transforms.json"), doc.to_string()).unwrap();
    tmp
}

/// A COLMAP model of one 8×6 pinhole camera posing `images` (id, name) along z.
fn model_of(images: &[(u32, &str)]) -> Model {
    Model {
        cameras: vec![Camera {
            id: 1,
            model: CameraModel::Pinhole,
            width: 8,
            height: 6,
            params: vec![10.0, 10.0, 4.0, 3.0],
        }],
        images: images
            .iter()
            .map(|&(id, name)| Image {
                id,
                qvec: [1.0, 0.0, 0.0, 0.0],
                tvec: [0.0, 0.0, 4.0 + f64::from(id)],
                camera_id: 1,
                name: name.into(),
                points2d: vec![],
            })
            .collect(),
        points: vec![],
    }
}

#[test]
fn nerf_paths_outside_the_dataset_are_refused_unless_allowed() {
    let tmp = nerf_scene(&["images/a.png", "../elsewhere/b.png"]);
    let scene = tmp.path().join("scene");
    let e = err("ingest-nerf", &scene, json!({}));
    for part in [
        "transforms.json",
        "frames[1]",
        "../elsewhere/b.png",
        "outside the dataset folder",
        "--allow-outside",
    ] {
        assert!(e.contains(part), "expected {part:?} in: {e}");
    }
    let ok = run(
        "ingest-nerf",
        &scene,
        json!({"allow-outside": true}),
        &Recorder::default(),
    );
    assert_eq!(ok.unwrap()["views"], 2);

    // Absolute paths leave the folder too, even when the file exists.
    let abs = tmp.path().join("abs.png");
    png(&abs);
    let tmp2 = nerf_scene(&["images/a.png"]);
    let scene2 = tmp2.path().join("scene");
    let doc = json!({"fl_x": 10.0, "w": 8, "h": 6, "frames": [
        {"file_path": "images/a.png", "transform_matrix": pose(4.0)},
        {"file_path": abs.to_str().unwrap(), "transform_matrix": pose(5.0)},
    ]});
    std::fs::write(scene2.join("transforms.json"), doc.to_string()).unwrap();
    let e = err("ingest-nerf", &scene2, json!({}));
    assert!(
        e.contains("frames[1]") && e.contains("--allow-outside"),
        "{e}"
    );
    // `..` that comes back inside is fine.
    let tmp3 = nerf_scene(&["images/../images/a.png", "images/b.png"]);
    run(
        "ingest-nerf",
        &tmp3.path().join("scene"),
        json!({}),
        &Recorder::default(),
    )
    .unwrap();
}

#[test]
fn colmap_image_names_outside_the_dataset_are_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = tmp.path().join("scene");
    png(&scene.join("images/a.png"));
    png(&tmp.path().join("x.png"));
    let model = model_of(&[(1, "a.png"), (2, "../../x.png")]);
    std::fs::create_dir_all(scene.join("sparse/0")).unwrap();
    colmap::write_bin(&model, &scene.join("sparse/0")).unwrap();
    let e = err("ingest-colmap", &scene, json!({}));
    for part in ["images.bin", "image 2", "../../x.png", "--allow-outside"] {
        assert!(e.contains(part), "expected {part:?} in: {e}");
    }
    let ok = run(
        "ingest-colmap",
        &scene,
        json!({"allow-outside": true}),
        &Recorder::default(),
    );
    assert_eq!(ok.unwrap()["views"], 2);
}

#[test]
fn downscale_beyond_the_image_size_is_refused_before_any_work() {
    let tmp = nerf_scene(&["images/a.png", "images/b.png"]);
    let scene = tmp.path().join("scene");
    let ctx = Recorder::default();
    let e = run("ingest-nerf", &scene, json!({"downscale": 7}), &ctx)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("downscale") && e.contains("8×6") && e.contains("at most 6"),
        "{e}"
    );
    assert!(ctx.0.lock().unwrap().is_empty(), "work was done first");
    let e = err("ingest-nerf", &scene, json!({"downscale": 0}));
    assert!(e.contains("downscale"), "{e}");
    run("ingest-nerf", &scene, json!({"downscale": 6}), &ctx).unwrap();
}

#[test]
fn a_hold_zero_marker_trains_on_every_view_and_warns() {
    let tmp = nerf_scene(&["images/a.png", "images/b.png", "images/c.png"]);
    let scene = tmp.path().join("scene");
    std::fs::write(scene.join("hold=0"), b"").unwrap();
    let ctx = Recorder::default();
    let summary = run("ingest-nerf", &scene, json!({}), &ctx).unwrap();
    assert_eq!(
        (summary["train"].as_u64(), summary["test"].as_u64()),
        (Some(3), Some(0))
    );
    let logs = ctx.0.lock().unwrap();
    assert!(
        logs.iter().any(|(level, m)| *level == LogLevel::Warn
            && m.contains("no test views")
            && m.contains("hold=0")
            && m.contains("--split train")),
        "{logs:?}"
    );
}

#[test]
fn photos_the_model_does_not_pose_are_named_with_the_test_views_they_shift() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = tmp.path().join("scene");
    let names = ["a.png", "b.png", "c.png", "d.png", "e.png"];
    for n in names {
        png(&scene.join("images").join(n));
    }
    // b.png is on disk but not in the model: the hold rule counts a, c, d, e.
    let model = model_of(&[(1, "a.png"), (3, "c.png"), (4, "d.png"), (5, "e.png")]);
    std::fs::create_dir_all(scene.join("sparse/0")).unwrap();
    colmap::write_bin(&model, &scene.join("sparse/0")).unwrap();
    let warned = |options: Value| {
        let ctx = Recorder::default();
        run("ingest-colmap", &scene, options, &ctx).unwrap();
        let logs = ctx.0.lock().unwrap();
        logs.iter()
            .find(|(level, m)| *level == LogLevel::Warn && m.contains("no pose"))
            .map(|(_, m)| m.clone())
    };
    let m = warned(json!({"hold": 2})).expect("no warning about b.png");
    for part in [
        "b.png",
        "multiples of 2",
        "4 posed views",
        "a.png, d.png",
        "--hold",
    ] {
        assert!(m.contains(part), "expected {part:?} in: {m}");
    }
    // Every view training has no test views to shift.
    assert_eq!(warned(json!({"hold": 0})), None);
    // A model posing every photo says nothing.
    std::fs::remove_file(scene.join("images/b.png")).unwrap();
    assert_eq!(warned(json!({"hold": 2})), None);
}

#[test]
fn downscaled_photos_whose_names_flatten_alike_stay_apart() {
    let tmp = nerf_scene(&[
        "images/x.png",
        "images/x.jpg",
        "images/a/b.png",
        "images/a_b.png",
    ]);
    let scene = tmp.path().join("scene");
    let stage = cocog_ingest::stages()
        .into_iter()
        .find(|s| s.info().name == "ingest-nerf")
        .unwrap();
    let info = stage.info();
    let options = Options::validate(
        &info.name,
        &info.options,
        &serde_json::Map::from_iter([("downscale".to_owned(), json!(2))]),
    )
    .unwrap();
    let out = tempfile::tempdir().unwrap();
    stage
        .run(
            &StageRequest {
                input: scene,
                output: out.path().to_path_buf(),
                options,
            },
            &Recorder::default(),
        )
        .unwrap();
    let written = cocog_pipeline::Scene::load(out.path()).unwrap();
    let mut images: Vec<&str> = written.views.iter().map(|v| v.image.as_str()).collect();
    images.sort();
    images.dedup();
    assert_eq!(images.len(), 4, "two views share a photo: {images:?}");
    for image in images {
        assert!(out.path().join(image).is_file(), "{image} missing");
    }
}

#[test]
fn a_split_value_that_is_neither_train_nor_test_is_refused_and_a_partial_split_said() {
    let tmp = nerf_scene(&["images/a.png", "images/b.png", "images/c.png"]);
    let scene = tmp.path().join("scene");
    let with_splits = |splits: [Option<&str>; 3]| {
        let frames: Vec<Value> = splits
            .iter()
            .enumerate()
            .map(|(i, s)| {
                let mut f = json!({
                    "file_path": format!("images/{}.png", ["a", "b", "c"][i]),
                    "transform_matrix": pose(4.0 + i as f64),
                });
                if let Some(s) = s {
                    f["split"] = json!(s);
                }
                f
            })
            .collect();
        let doc = json!({"fl_x": 10.0, "w": 8, "h": 6, "frames": frames});
        std::fs::write(scene.join("transforms.json"), doc.to_string()).unwrap();
    };
    with_splits([Some("train"), Some("Test"), Some("test")]);
    let e = err("ingest-nerf", &scene, json!({}));
    for part in ["transforms.json", "frames[1]", "split", "\"Test\""] {
        assert!(e.contains(part), "expected {part:?} in: {e}");
    }
    with_splits([Some("train"), Some("val"), Some("test")]);
    let summary = run("ingest-nerf", &scene, json!({}), &Recorder::default()).unwrap();
    assert_eq!(
        (summary["split"].as_str(), summary["test"].as_u64()),
        (Some("dataset"), Some(2))
    );
    with_splits([Some("train"), None, Some("test")]);
    let ctx = Recorder::default();
    let summary = run("ingest-nerf", &scene, json!({}), &ctx).unwrap();
    assert_eq!(summary["split"], "hold=8");
    let logs = ctx.0.lock().unwrap();
    assert!(
        logs.iter().any(|(level, m)| *level == LogLevel::Warn
            && m.contains("2 of 3 views declare a split")
            && m.contains("frames[1]")),
        "{logs:?}"
    );
}

#[test]
fn hold_one_is_refused_and_a_partial_images_n_folder_is_said() {
    let tmp = nerf_scene(&["images/a.png", "images/b.png", "images/c.png"]);
    let scene = tmp.path().join("scene");
    let e = err("ingest-nerf", &scene, json!({"hold": 1}));
    assert!(e.contains("--hold 1") && e.contains("--hold 8"), "{e}");
    std::fs::create_dir_all(scene.join("images_2")).unwrap();
    image::RgbImage::new(4, 3)
        .save(scene.join("images_2/a.png"))
        .unwrap();
    let ctx = Recorder::default();
    run("ingest-nerf", &scene, json!({"downscale": 2}), &ctx).unwrap();
    let logs = ctx.0.lock().unwrap();
    assert!(
        logs.iter().any(|(level, m)| *level == LogLevel::Warn
            && m.contains("images_2")
            && m.contains("2 of 3 photos")
            && m.contains("b.png")),
        "{logs:?}"
    );
}
