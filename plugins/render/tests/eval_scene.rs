//! `eval-scene` scores its renders exactly as `eval` scores the same folders.

mod common;

use cocog_eval::{EvalOptions, LpipsMode, evaluate_dirs};
use common::{gpu_available, reference_png, run, stage, write_scene};
use serde_json::{Value, json};

/// A scene whose test photo is `photo`, scored by `eval-scene` into `tmp/metrics.json`.
fn score(tmp: &std::path::Path, photo: &image::RgbImage) -> (std::path::PathBuf, Value) {
    let scene = tmp.join("scene");
    write_scene(&scene, photo);
    let report = run(
        stage("eval-scene").as_ref(),
        &scene,
        &tmp.join("metrics.json"),
        json!({"lpips": "off"}),
    )
    .unwrap();
    (scene, report)
}

/// PSNR from a report; identical images have +inf, which JSON stores as null.
fn psnr(report: &Value) -> f64 {
    report["mean"]["psnr"].as_f64().unwrap_or(f64::INFINITY)
}

#[test]
fn photos_equal_to_the_reference_score_near_perfect() {
    if !gpu_available() {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let (exact, _) = reference_png();
    let (scene, report) = score(tmp.path(), &exact);
    eprintln!("eval-scene on exact photos: {}", report["mean"]);
    assert_eq!(
        (report["views"].as_u64(), report["split"].as_str()),
        (Some(1), Some("test"))
    );
    assert!(psnr(&report) > 40.0, "{}", report["mean"]);
    let ssim = report["mean"]["ssim_gaussian11"].as_f64().unwrap();
    assert!(ssim > 0.99, "{}", report["mean"]);
    // The scratch folders are gone, so the report names the scene and its photos instead.
    assert!(report.get("pred_dir").is_none(), "{report}");
    assert_eq!(report["scene"], json!(scene));
    assert_eq!(report["images"][0]["gt"], json!(scene.join("images/a.png")));
    assert!(
        std::fs::read_dir(tmp.path()).unwrap().all(|e| !e
            .unwrap()
            .file_name()
            .to_string_lossy()
            .starts_with('.')),
        "the scratch renders are removed"
    );
}

#[test]
fn perturbed_photos_score_what_eval_scores_on_the_renders() {
    if !gpu_available() {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let (mut photo, _) = reference_png();
    for (i, p) in photo.pixels_mut().enumerate() {
        p.0[i % 3] = p.0[i % 3].saturating_add((i % 7) as u8 * 6);
    }
    let (scene, report) = score(tmp.path(), &photo);
    let metrics = tmp.path().join("metrics.json");
    let written: Value = serde_json::from_slice(&std::fs::read(&metrics).unwrap()).unwrap();
    assert_eq!(written, report);
    assert!(psnr(&report) < 40.0, "{}", report["mean"]);

    // The same renders scored by `eval`'s code straight from the two folders.
    let renders = tmp.path().join("renders");
    std::fs::create_dir(&renders).unwrap();
    run(stage("render").as_ref(), &scene, &renders, json!({})).unwrap();
    let opts = EvalOptions {
        lpips: LpipsMode::Off,
        ..EvalOptions::default()
    };
    let direct = evaluate_dirs(&renders, &scene.join("images"), &opts, &())
        .unwrap()
        .to_json();
    eprintln!("eval-scene {} vs eval {}", report["mean"], direct["mean"]);
    for key in ["psnr", "ssim_deblurnerf", "ssim_gaussian11"] {
        let (a, b) = (&report["mean"][key], &direct["mean"][key]);
        assert!(
            (a.as_f64().unwrap() - b.as_f64().unwrap()).abs() < 1e-9,
            "{key}: {a} vs {b}"
        );
    }
    assert_eq!(report["images"][0]["name"], "a");
}

/// Photos with alpha are scored over the colour the scene was trained over, and renders
/// default to it: the photo is the f64 reference render's colour and coverage as straight
/// RGBA, so over white it must equal the reference rendered over white.
#[test]
fn alpha_photos_are_scored_over_the_training_background() {
    if !gpu_available() {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let scene = tmp.path().join("scene");
    let (exact, _) = reference_png();
    write_scene(&scene, &exact);
    let over_black = common::reference_render([0.0; 3]);
    let straight = image::RgbaImage::from_fn(over_black.width, over_black.height, |x, y| {
        let i = (y * over_black.width + x) as usize;
        let a = over_black.alpha[i];
        let q = |v: f64| (v.clamp(0.0, 1.0) * 255.0).round() as u8;
        let c = over_black.color[i].map(|c| if a > 1e-9 { q(c / a) } else { 0 });
        image::Rgba([c[0], c[1], c[2], q(a)])
    });
    assert!(
        over_black.alpha.iter().any(|&a| a < 0.5),
        "the test needs uncovered pixels"
    );
    straight.save(scene.join("images/a.png")).unwrap();
    let mut manifest = cocog_pipeline::Scene::load(&scene).unwrap();
    manifest.history.push(cocog_pipeline::HistoryEntry {
        stage: "train".into(),
        provider: "built-in".into(),
        input: "elsewhere".into(),
        options: json!({}),
        resolved: Some(json!({ "background": [1.0, 1.0, 1.0] })),
        cocog_version: "test".into(),
        finished_at: 0,
    });
    manifest.save(&scene).unwrap();
    assert_eq!(manifest.trained_background(), Some([1.0; 3]));

    let report = run(
        stage("eval-scene").as_ref(),
        &scene,
        &tmp.path().join("metrics.json"),
        json!({"lpips": "off"}),
    )
    .unwrap();
    eprintln!("eval-scene of RGBA photos over white: {}", report["mean"]);
    assert!(psnr(&report) > 40.0, "{}", report["mean"]);

    // render defaults to the training colour too: uncovered pixels come out white.
    let renders = tmp.path().join("renders");
    std::fs::create_dir(&renders).unwrap();
    run(stage("render").as_ref(), &scene, &renders, json!({})).unwrap();
    let img = image::open(renders.join("a.png")).unwrap().to_rgb8();
    let over_white = common::reference_render([1.0; 3]);
    for (i, p) in img.pixels().enumerate() {
        let want = over_white.color[i].map(|c| c.clamp(0.0, 1.0) * 255.0);
        for c in 0..3 {
            assert!(
                (f64::from(p.0[c]) - want[c]).abs() <= 2.0,
                "pixel {i}: {p:?} vs {want:?}"
            );
        }
    }
}

#[test]
fn a_view_too_small_to_score_is_named_by_its_photo() {
    if !gpu_available() {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let (exact, _) = reference_png();
    let scene = tmp.path().join("scene");
    write_scene(&scene, &exact);
    let err = run(
        stage("eval-scene").as_ref(),
        &scene,
        &tmp.path().join("metrics.json"),
        json!({"lpips": "off", "downscale": 4}),
    )
    .unwrap_err()
    .to_string();
    // The renders were scratch files beside the output; the photo is what the user knows.
    let photo = scene.join("images/a.png");
    assert!(
        err.starts_with(&format!(
            "{}: scored at 10x8 (downscale 4); SSIM needs",
            photo.display()
        )) && !err.contains("scratch"),
        "{err}"
    );
}
