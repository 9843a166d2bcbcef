//! A tiny trained-looking scene and its f64 reference render, shared by the stage tests.

#![allow(dead_code)] // Each test binary uses its own subset.

use std::path::Path;

use cocog_engine::reference::{Gaussians64, Image64, render};
use cocog_engine::{Camera, GaussianParams};
use cocog_pipeline::{
    Camera as SceneCamera, NullContext, Options, Scene, Split, Stage, StageError, StageRequest,
    View,
};
use serde_json::{Map, Value};

pub const W: u32 = 40;
pub const H: u32 = 30;

pub fn gpu_available() -> bool {
    cocog_engine::test_gpu().is_some()
}

/// Uniform noise in [0, 1) from a counter (no generator state to carry around).
pub fn noise(i: u64) -> f32 {
    let mut z = i
        .wrapping_mul(0x9E37_79B9_7F4A_7C15)
        .wrapping_add(0x6A09_E667);
    z = (z ^ (z >> 29)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    ((z ^ (z >> 32)) >> 40) as f32 / (1u64 << 24) as f32
}

/// 60 Gaussians in front of an identity camera (z 2..5), degree 1.
pub fn gaussians() -> GaussianParams {
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

pub fn identity() -> [[f64; 4]; 4] {
    let mut m = [[0.0; 4]; 4];
    for (i, row) in m.iter_mut().enumerate() {
        row[i] = 1.0;
    }
    m
}

pub fn camera() -> Camera {
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
pub fn write_scene(dir: &Path, photo: &image::RgbImage) {
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

pub fn run(
    stage: &dyn Stage,
    input: &Path,
    output: &Path,
    given: Value,
) -> Result<Value, StageError> {
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

pub fn stage(name: &str) -> Box<dyn Stage> {
    cocog_render::stages()
        .into_iter()
        .find(|s| s.info().name == name)
        .unwrap()
}

/// The f64 reference render of the test Gaussians over `background`.
pub fn reference_render(background: [f64; 3]) -> Image64 {
    render(&Gaussians64::from(&gaussians()), &camera(), background)
}

/// The f64 reference image quantised as the stage quantises.
pub fn reference_png() -> (image::RgbImage, Image64) {
    let img = reference_render([0.0; 3]);
    let bytes = img
        .color
        .iter()
        .flatten()
        .map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8)
        .collect();
    (image::RgbImage::from_raw(W, H, bytes).unwrap(), img)
}
