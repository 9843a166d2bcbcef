//! `render` against the engine's f64 CPU reference: every 8-bit level, and depth ÷ alpha.

mod common;

use cocog_formats::exr_map::read_exr;
use cocog_pipeline::{Scene, Split};
use common::{H, W, gpu_available, reference_png, run, stage, write_scene};
use serde_json::json;

#[test]
fn rendered_png_and_depth_match_the_f64_reference() {
    if !gpu_available() {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let (want, reference) = reference_png();
    let scene = tmp.path().join("scene");
    write_scene(&scene, &want);
    let out = tmp.path().join("out");
    std::fs::create_dir(&out).unwrap();
    let summary = run(
        stage("render").as_ref(),
        &scene,
        &out,
        json!({"depth": true, "split": "all"}),
    )
    .unwrap();
    assert_eq!(summary["views"], 2);
    let got = image::open(out.join("a.png")).unwrap().to_rgb8();
    assert_eq!(got.dimensions(), (W, H));
    let worst = got
        .as_raw()
        .iter()
        .zip(want.as_raw())
        .map(|(a, b)| a.abs_diff(*b))
        .max()
        .unwrap();
    assert!(worst <= 1, "8-bit levels off by {worst}");
    assert!(
        want.as_raw().iter().any(|&v| v > 20),
        "the scene is visible"
    );

    let depth = read_exr(&out.join("depth/a.exr")).unwrap();
    assert_eq!((depth.width, depth.height), (W as usize, H as usize));
    for (i, d) in depth.data.iter().enumerate() {
        let (a, z) = (reference.alpha[i], reference.depth[i]);
        let expected = if a > 1e-6 { z / a } else { 0.0 };
        // Where alpha is tiny, depth/alpha amplifies float rounding.
        let tolerance = 1e-3 * expected.abs().max(1.0) / a.clamp(1e-2, 1.0);
        assert!(
            (f64::from(*d) - expected).abs() < tolerance,
            "pixel {i}: {d} vs {expected} (alpha {a})"
        );
    }
}

#[test]
fn downscaled_cameras_scale_every_intrinsic_by_the_size_ratio() {
    let tmp = tempfile::tempdir().unwrap();
    let (png, _) = reference_png();
    write_scene(tmp.path(), &png);
    let scene = Scene::load(tmp.path()).unwrap();
    let views = cocog_render::split_cameras(&scene, tmp.path(), Some(Split::Test), 2).unwrap();
    assert_eq!(views.len(), 1);
    assert_eq!(
        (views[0].name.as_str(), views[0].stem()),
        ("a.png", "a".into())
    );
    let c = views[0].camera;
    assert_eq!((c.width, c.height), (W / 2, H / 2));
    assert_eq!((c.fx, c.fy, c.cx, c.cy), (18.0, 18.0, 10.0, 7.5));
    let all = cocog_render::split_cameras(&scene, tmp.path(), None, 1).unwrap();
    assert_eq!(all.len(), 2);
}

#[test]
fn a_view_renders_under_one_name_whichever_split_is_chosen() {
    let tmp = tempfile::tempdir().unwrap();
    let (png, _) = reference_png();
    write_scene(tmp.path(), &png);
    let mut scene = Scene::load(tmp.path()).unwrap();
    // NeRF-synthetic's layout: a test and a training view share the stem r_0.
    scene.views[0].name = "test/r_0.png".into();
    scene.views[1].name = "train/r_0.png".into();
    scene.save(tmp.path()).unwrap();
    let outputs = |split| {
        cocog_render::split_cameras(&scene, tmp.path(), split, 1)
            .unwrap()
            .into_iter()
            .map(|c| c.output)
            .collect::<Vec<_>>()
    };
    assert_eq!(outputs(Some(Split::Test)), ["test_r_0"]);
    assert_eq!(outputs(Some(Split::Train)), ["train_r_0"]);
    assert_eq!(outputs(None), ["test_r_0", "train_r_0"]);

    // `--views r_0` is then ambiguous over both splits; the full or the render name is not.
    let out = tmp.path().join("out");
    std::fs::create_dir(&out).unwrap();
    let err = run(
        stage("render").as_ref(),
        tmp.path(),
        &out,
        json!({"views": "r_0", "split": "all"}),
    )
    .unwrap_err()
    .to_string();
    assert!(
        err.contains(
            "\"r_0\" names more than one view (test/r_0.png, train/r_0.png); give the full \
             name or the render name (test_r_0 or train_r_0)"
        ),
        "{err}"
    );
    if !gpu_available() {
        return;
    }
    let summary = run(
        stage("render").as_ref(),
        tmp.path(),
        &out,
        json!({"views": "train_r_0,test/r_0.png", "split": "all"}),
    )
    .unwrap();
    assert_eq!(summary["views"], 2);
    assert!(out.join("train_r_0.png").is_file() && out.join("test_r_0.png").is_file());
}

#[test]
fn an_unknown_view_is_named_with_the_split_it_was_looked_for_in() {
    let tmp = tempfile::tempdir().unwrap();
    let (png, _) = reference_png();
    let scene = tmp.path().join("scene");
    write_scene(&scene, &png);
    let out = tmp.path().join("out");
    std::fs::create_dir(&out).unwrap();
    let err = |given| {
        run(stage("render").as_ref(), &scene, &out, given)
            .unwrap_err()
            .to_string()
    };
    let test = err(json!({"views": "b"}));
    assert!(
        test.contains("no view named \"b\" in test (views: a.png); --split train or --split all"),
        "{test}"
    );
    let train = err(json!({"views": "a", "split": "train"}));
    assert!(train.contains("--split test or --split all"), "{train}");
    let all = err(json!({"views": "c", "split": "all"}));
    assert!(all.contains("in the scene (views: a.png, b.png)"), "{all}");
    assert!(!all.contains("--split"), "{all}");
}
