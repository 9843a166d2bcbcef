//! Refocused renders through a scene's lens model: aperture 0 is the sharp render bit for
//! bit, a focus pull writes its frames, `--as-photographed` gives training views their own
//! lens, and bad requests fail naming what is wrong before anything is written.

mod common;

use std::path::Path;

use cocog_engine::coc::{CocConfig, CocVariant, init_weights};
use cocog_engine::nn::CompositorConfig;
use cocog_formats::lens_model::LensModel;
use cocog_pipeline::{Scene, StageError};
use common::{gpu_available, reference_png, run, stage, write_scene};
use serde_json::{Value, json};

/// An untrained lens model of `variant` for the common scene (one training view, b.png).
fn lens_model(variant: CocVariant) -> LensModel {
    let config = CocConfig {
        centred: true,
        ..CocConfig::new(variant)
    };
    let channels = 4;
    LensModel {
        variant: variant.name().into(),
        copies: config.copies,
        width: config.width,
        centred: true,
        modulate_base: true,
        compositor_channels: channels,
        compositor_trained: true,
        mlp: init_weights(&config.mlp(), 5),
        compositor: CompositorConfig::with_channels(channels).layout().init(6),
        origin: [0.0, 0.0, 0.0],
        scale: 5.0,
        // b.png was "photographed" focused 3 units away.
        focus_distances: vec![3.0],
        apertures: vec![0.02],
    }
}

fn cocog_scene(dir: &Path, variant: CocVariant) {
    let (png, _) = reference_png();
    write_scene(dir, &png);
    lens_model(variant)
        .save(&dir.join("lens-model.safetensors"))
        .unwrap();
    let mut s = Scene::load(dir).unwrap();
    s.lens_model = Some("lens-model.safetensors".into());
    s.save(dir).unwrap();
}

fn render(scene: &Path, out: &Path, options: Value) -> Result<Value, StageError> {
    std::fs::create_dir_all(out).unwrap();
    run(stage("render").as_ref(), scene, out, options)
}

fn png(path: &Path) -> Vec<u8> {
    image::open(path).unwrap().to_rgb8().into_raw()
}

#[test]
fn aperture_zero_is_the_sharp_render_and_a_lens_blurs() {
    if !gpu_available() {
        return;
    }
    for variant in [CocVariant::Code, CocVariant::Lens] {
        let tmp = tempfile::tempdir().unwrap();
        let scene = tmp.path().join("scene");
        cocog_scene(&scene, variant);
        let sharp = tmp.path().join("sharp");
        render(&scene, &sharp, json!({"split": "all"})).unwrap();
        let zero = tmp.path().join("zero");
        let s = render(
            &scene,
            &zero,
            json!({"split": "all", "focus_distance": "2.5", "aperture": 0.0}),
        )
        .unwrap();
        assert_eq!(s["lenses"][0]["aperture"], 0.0, "{s}");
        for v in ["a", "b"] {
            let (x, y) = (
                png(&sharp.join(format!("{v}.png"))),
                png(&zero.join(format!("{v}.png"))),
            );
            assert!(
                x == y,
                "{variant:?} {v}: aperture 0 must equal the sharp render"
            );
        }
        let wide = tmp.path().join("wide");
        render(
            &scene,
            &wide,
            json!({"views": "a", "focus_distance": "2.5", "aperture": 3.0}),
        )
        .unwrap();
        let (x, y) = (png(&sharp.join("a.png")), png(&wide.join("a.png")));
        let differ = x.iter().zip(&y).filter(|(p, q)| p != q).count();
        assert!(
            differ > x.len() / 10,
            "{variant:?}: a wide aperture must change the render ({differ} of {} bytes)",
            x.len()
        );
        // The default blend is F when training learned it (this model says so), and the mean
        // of the sets when training never reached F's start.
        let mean = tmp.path().join("mean");
        let wide_mean =
            json!({"views": "a", "focus_distance": "2.5", "aperture": 3.0, "composite": "mean"});
        render(&scene, &mean, wide_mean).unwrap();
        let m = png(&mean.join("a.png"));
        assert_ne!(
            m, y,
            "{variant:?}: F and the mean must blend differently here"
        );
        let mut model = lens_model(variant);
        model.compositor_trained = false;
        model.save(&scene.join("lens-model.safetensors")).unwrap();
        let untrained = tmp.path().join("untrained");
        let wide_default = json!({"views": "a", "focus_distance": "2.5", "aperture": 3.0});
        render(&scene, &untrained, wide_default).unwrap();
        assert_eq!(
            png(&untrained.join("a.png")),
            m,
            "{variant:?}: untrained F is not used"
        );
    }
}

#[test]
fn photographed_lenses_pulls_and_focus_points() {
    if !gpu_available() {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let scene = tmp.path().join("scene");
    cocog_scene(&scene, CocVariant::Lens);
    // Training views get their own lens; the test view, which has none, renders sharp.
    let out = tmp.path().join("photographed");
    let s = render(
        &scene,
        &out,
        json!({"split": "all", "as_photographed": true}),
    )
    .unwrap();
    let lenses = s["lenses"].as_array().unwrap();
    let lens_of = |v: &str| lenses.iter().find(|l| l["view"] == v).unwrap().clone();
    assert_eq!(lens_of("b.png")["focus_distance"], 3.0);
    assert_eq!(lens_of("a.png")["focus_distance"], Value::Null);
    // from:VIEW takes that photo's focus.
    let out = tmp.path().join("from");
    let s = render(
        &scene,
        &out,
        json!({"views": "a", "focus_distance": "from:b"}),
    )
    .unwrap();
    assert_eq!(s["lenses"][0]["focus_distance"], 3.0);
    // A focus at a pixel: the distance of the surface the f64 reference sees there, taken
    // at the most solid pixel of the test view (which shares the training view's pose).
    let (_, reference) = reference_png();
    let i = (0..reference.alpha.len())
        .max_by(|&a, &b| reference.alpha[a].total_cmp(&reference.alpha[b]))
        .unwrap();
    let (x, y) = (i as u32 % reference.width, i as u32 / reference.width);
    let cam = common::camera();
    let (rx, ry) = (
        (f64::from(x) + 0.5 - cam.cx) / cam.fx,
        (f64::from(y) + 0.5 - cam.cy) / cam.fy,
    );
    let want = reference.depth[i] / reference.alpha[i] * (1.0 + rx * rx + ry * ry).sqrt();
    let out = tmp.path().join("at");
    let s = render(
        &scene,
        &out,
        json!({"views": "a", "focus_at": format!("{x},{y}")}),
    )
    .unwrap();
    let d = s["lenses"][0]["focus_distance"].as_f64().unwrap();
    assert!(
        (d - want).abs() < 1e-3 * want,
        "focus at ({x}, {y}): {d}, the reference sees {want}"
    );
    // A pull: frames even in 1/distance, near to far.
    let out = tmp.path().join("pull");
    let s = render(&scene, &out, json!({"views": "a", "focus_sweep": "1:4:5"})).unwrap();
    assert_eq!(s["frames"], 5);
    let d: Vec<f64> = s["lenses"]
        .as_array()
        .unwrap()
        .iter()
        .map(|l| l["focus_distance"].as_f64().unwrap())
        .collect();
    assert!(
        (d[0] - 1.0).abs() < 1e-6 && (d[4] - 4.0).abs() < 1e-5,
        "{d:?}"
    );
    assert!(
        (1.0 / d[2] - 0.625).abs() < 1e-6,
        "the middle frame is even in 1/d: {d:?}"
    );
    for i in 0..5 {
        assert!(out.join(format!("frame-{i:03}.png")).is_file());
    }
}

#[test]
fn bad_refocus_requests_name_what_is_wrong_and_write_nothing() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = tmp.path().join("scene");
    cocog_scene(&scene, CocVariant::Code);
    let cases = [
        (json!({"focus_distance": "-1"}), "positive distance"),
        (json!({"focus_distance": "NaN"}), "positive distance"),
        (
            json!({"focus_distance": "2", "aperture": -0.5}),
            "0 or more",
        ),
        (json!({"aperture": 2.0}), "needs a focus"),
        (
            json!({"focus_distance": "from:zzz"}),
            "no training view named \"zzz\"",
        ),
        (
            json!({"focus_distance": "2", "views": "q"}),
            "no view named \"q\" in test (views: a.png); --split train",
        ),
        (json!({"focus_at": "3"}), "X,Y"),
        (
            json!({"focus_distance": "2", "as_photographed": true}),
            "choose one",
        ),
        (json!({"focus_sweep": "1:2:3"}), "one view"),
        (
            json!({"views": "a", "focus_sweep": "1:2"}),
            "NEAR:FAR:FRAMES",
        ),
        (
            json!({"focus_distance": "2", "composite": "max"}),
            "learned or mean",
        ),
    ];
    for (options, needle) in cases {
        let out = tmp.path().join("out");
        let err = render(&scene, &out, options.clone()).unwrap_err();
        assert!(
            err.to_string().contains(needle),
            "{options}: {needle:?} not in {err}"
        );
        let written = std::fs::read_dir(&out).unwrap().count();
        assert_eq!(written, 0, "{options}: nothing may be written");
        std::fs::remove_dir(&out).unwrap();
    }
}

/// `camera`: new cameras from a JSON file render as the scene's own views do at the same
/// pose (sharp and refocused, bit for bit), a moved camera sees something else, and bad
/// files fail naming the file, the camera and the field, with nothing written.
#[test]
fn new_cameras_from_a_pose_file() {
    if !gpu_available() {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let scene = tmp.path().join("scene");
    cocog_scene(&scene, CocVariant::Code);
    let pose = |x: f64| {
        json!([
            [1.0, 0.0, 0.0, x],
            [0.0, 1.0, 0.0, 0.0],
            [0.0, 0.0, 1.0, 0.0],
            [0.0, 0.0, 0.0, 1.0]
        ])
    };
    let file = tmp.path().join("cameras.json");
    std::fs::write(
        &file,
        json!([
            {"name": "same", "world_from_camera": pose(0.0), "camera": 1},
            {"name": "moved", "world_from_camera": pose(0.3)}
        ])
        .to_string(),
    )
    .unwrap();
    for refocus in [json!({}), json!({"focus_distance": 2.5, "aperture": 3.0})] {
        let mut given = refocus.as_object().unwrap().clone();
        given.insert("views".into(), json!("a"));
        let views = tmp.path().join("views");
        render(&scene, &views, Value::Object(given.clone())).unwrap();
        given.remove("views");
        given.insert("camera".into(), json!(file));
        let novel = tmp.path().join("novel");
        let s = render(&scene, &novel, Value::Object(given)).unwrap();
        assert_eq!(s["views"], 2);
        let a = png(&views.join("a.png"));
        assert_eq!(
            png(&novel.join("same.png")),
            a,
            "{refocus}: same pose, same render"
        );
        let moved = png(&novel.join("moved.png"));
        let differ = moved.iter().zip(&a).filter(|(p, q)| p != q).count();
        assert!(
            differ > a.len() / 10,
            "{refocus}: a moved camera sees the same"
        );
        std::fs::remove_dir_all(&views).unwrap();
        std::fs::remove_dir_all(&novel).unwrap();
    }

    let bad_cases = [
        (
            json!({"world_from_camera": [[1.0, 0.5, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]]}),
            vec!["camera 0", "world_from_camera", "orthonormal"],
        ),
        (
            json!([{"world_from_camera": pose(0.0), "camera": 7}]),
            vec!["camera 0", "`camera` 7", "ids: 1"],
        ),
        (
            json!({"pose": 1}),
            vec!["world_from_camera", "expected a camera"],
        ),
        (json!([]), vec!["empty"]),
    ];
    for (content, needles) in bad_cases {
        std::fs::write(&file, content.to_string()).unwrap();
        let out = tmp.path().join("bad");
        let err = render(&scene, &out, json!({"camera": file})).unwrap_err();
        assert!(matches!(err, StageError::Input(_)), "{err:?}");
        for n in needles.iter().chain(&["cameras.json"]) {
            assert!(err.to_string().contains(n), "{n:?} not in {err}");
        }
        assert_eq!(std::fs::read_dir(&out).unwrap().count(), 0, "{content}");
    }
    let err = render(
        &scene,
        &tmp.path().join("both"),
        json!({"camera": file, "views": "a"}),
    )
    .unwrap_err();
    assert!(err.to_string().contains("either"), "{err}");
}
