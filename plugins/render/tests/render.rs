//! `render` and `eval-scene` against the engine's f64 CPU reference.

use std::path::Path;

use cocog_engine::reference::{Gaussians64, render};
use cocog_engine::{Camera, GaussianParams};
use cocog_formats::exr_map::read_exr;
use cocog_pipeline::{
    Camera as SceneCamera, NullContext, Options, Scene, Split, Stage, StageError, StageRequest,
    View,
};
use serde_json::{Map, Value, json};

const W: u32 = 40;
const H: u32 = 30;

fn gpu_available() -> bool {
    cocog_engine::test_gpu().is_some()
}

/// Uniform noise in [0, 1) from a counter (no generator state to carry around).
fn noise(i: u64) -> f32 {
    let mut z = i
        .wrapping_mul(0x9E37_79B9_7F4A_7C15)
        .wrapping_add(0x6A09_E667);
    z = (z ^ (z >> 29)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    ((z ^ (z >> 32)) >> 40) as f32 / (1u64 << 24) as f32
}

/// 60 Gaussians in front of an identity camera (z 2..5), degree 1.
fn gaussians() -> GaussianParams {
    let mut k = 0u64;
    let mut u = |lo: f32, hi: f32| {
        k += 1;
        lo + (hi - lo) * noise(k)
    };
    let mut g = GaussianParams {
        sh_degree: 1,
        ..Default::default()
    };
    for _ in 0..60 {
        let z = u(2.0, 5.0);
        g.means.push([u(-0.6, 0.6) * z, u(-0.45, 0.45) * z, z]);
        g.log_scales
            .push([u(-3.0, -1.8), u(-3.0, -1.8), u(-3.0, -1.8)]);
        g.quats
            .push([u(-1.0, 1.0), u(-1.0, 1.0), u(-1.0, 1.0), u(-1.0, 1.0)]);
        g.opacity_logits.push(u(-1.0, 3.0));
        g.sh.extend((0..12).map(|_| u(-0.8, 0.8)));
    }
    g
}

fn identity() -> [[f64; 4]; 4] {
    let mut m = [[0.0; 4]; 4];
    for (i, row) in m.iter_mut().enumerate() {
        row[i] = 1.0;
    }
    m
}

fn camera() -> Camera {
    Camera {
        fx: 36.0,
        fy: 36.0,
        cx: 20.0,
        cy: 15.0,
        width: W,
        height: H,
        world_from_camera: identity(),
    }
}

/// A trained-looking scene: one test view (`a.png`, whose photo is `photo`) and one train
/// view, both at the identity pose, and `gaussians.ply`.
fn write_scene(dir: &Path, photo: &image::RgbImage) {
    std::fs::create_dir_all(dir.join("images")).unwrap();
    photo.save(dir.join("images/a.png")).unwrap();
    photo.save(dir.join("images/b.png")).unwrap();
    let view = |name: &str, split| View {
        name: name.into(),
        image: format!("images/{name}"),
        camera: 1,
        world_from_camera: identity(),
        split,
        lens: None,
        depth: None,
    };
    let scene = Scene {
        cameras: vec![SceneCamera {
            id: 1,
            width: W,
            height: H,
            fx: 36.0,
            fy: 36.0,
            cx: 20.0,
            cy: 15.0,
        }],
        views: vec![view("a.png", Split::Test), view("b.png", Split::Train)],
        gaussians: Some("gaussians.ply".into()),
        ..Scene::default()
    };
    scene.save(dir).unwrap();
    let splats = (&gaussians()).into();
    cocog_formats::ply::write_splats(&dir.join("gaussians.ply"), &splats, None).unwrap();
}

fn run(stage: &dyn Stage, input: &Path, output: &Path, given: Value) -> Result<Value, StageError> {
    let info = stage.info();
    let given: Map<String, Value> = given.as_object().cloned().unwrap_or_default();
    let options = Options::validate(&info.name, &info.options, &given)?;
    let req = StageRequest {
        input: input.to_owned(),
        output: output.to_owned(),
        options,
    };
    stage.run(&req, &NullContext)
}

fn stage(name: &str) -> Box<dyn Stage> {
    cocog_render::stages()
        .into_iter()
        .find(|s| s.info().name == name)
        .unwrap()
}

/// The f64 reference image quantised as the stage quantises.
fn reference_png() -> (image::RgbImage, cocog_engine::reference::Image64) {
    let img = render(&Gaussians64::from(&gaussians()), &camera(), [0.0; 3]);
    let bytes = img
        .color
        .iter()
        .flatten()
        .map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8)
        .collect();
    (image::RgbImage::from_raw(W, H, bytes).unwrap(), img)
}

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
fn eval_scene_scores_renders_like_eval_does_on_the_same_folders() {
    if !gpu_available() {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let (exact, _) = reference_png();
    // The photo differs from the render by a known pattern.
    let mut photo = exact.clone();
    for (i, p) in photo.pixels_mut().enumerate() {
        p.0[i % 3] = p.0[i % 3].saturating_add((i % 7) as u8 * 6);
    }
    let scene = tmp.path().join("scene");
    write_scene(&scene, &photo);
    let metrics = tmp.path().join("metrics.json");
    let summary = run(
        stage("eval-scene").as_ref(),
        &scene,
        &metrics,
        json!({"lpips": "off"}),
    )
    .unwrap();
    assert_eq!(summary["views"], 1);
    assert_eq!(summary["split"], "test");
    let written: Value = serde_json::from_slice(&std::fs::read(&metrics).unwrap()).unwrap();
    assert_eq!(written, summary);

    // Direct PSNR of the reference render against the photo, in f64.
    let mse: f64 = exact
        .as_raw()
        .iter()
        .zip(photo.as_raw())
        .map(|(a, b)| (f64::from(*a) - f64::from(*b)) / 255.0)
        .map(|d| d * d)
        .sum::<f64>()
        / f64::from(3 * W * H);
    let psnr = -10.0 * mse.log10();
    let got = summary["mean"]["psnr"].as_f64().unwrap();
    eprintln!("eval-scene PSNR {got:.3} dB, direct {psnr:.3} dB");
    // Renders match the reference to ±1 level, which moves PSNR by well under 0.5 dB here.
    assert!((got - psnr).abs() < 0.5, "{got} vs {psnr}");
}

#[test]
fn bad_requests_name_what_is_wrong() {
    let tmp = tempfile::tempdir().unwrap();
    let (png, _) = reference_png();
    let scene = tmp.path().join("scene");
    write_scene(&scene, &png);
    let out = tmp.path().join("out");
    let render = stage("render");
    let err = run(
        render.as_ref(),
        &scene,
        &out,
        json!({"focus_distance": 2.0}),
    )
    .unwrap_err();
    assert!(matches!(err, StageError::Options(_)), "{err:?}");
    assert!(err.to_string().contains("CoCoGaussian"), "{err}");
    let err = run(render.as_ref(), &scene, &out, json!({"split": "dev"})).unwrap_err();
    assert!(err.to_string().contains("test, train or all"), "{err}");

    let mut s = Scene::load(&scene).unwrap();
    s.views.retain(|v| v.split == Split::Train);
    s.save(&scene).unwrap();
    let err = run(render.as_ref(), &scene, &out, json!({})).unwrap_err();
    assert!(err.to_string().contains("no test views"), "{err}");

    s.gaussians = None;
    s.save(&scene).unwrap();
    let err = run(render.as_ref(), &scene, &out, json!({"split": "all"})).unwrap_err();
    assert!(matches!(err, StageError::Input(_)), "{err:?}");
    assert!(err.to_string().contains("`gaussians`"), "{err}");
}
