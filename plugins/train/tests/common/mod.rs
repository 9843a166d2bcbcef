//! Shared by the GPU tests: a known Gaussian scene, a camera ring, PSNR of held-out views.
#![allow(dead_code)]

use cocog_engine::{Batch, Camera, GaussianParams, GpuContext, Renderer, View};
use cocog_metrics::{FloatImage, psnr};
use cocog_train::{SplitMix64, TrainView, Trainer, init_from_points};

pub const W: u32 = 48;
pub const H: u32 = 36;

pub use cocog_engine::test_gpu as gpu;

/// A camera at `eye` looking at the origin (OpenCV axes: columns right, down, forward).
pub fn look_at_origin(eye: [f64; 3]) -> Camera {
    let norm = |v: [f64; 3]| {
        let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        v.map(|x| x / l)
    };
    let cross = |a: [f64; 3], b: [f64; 3]| {
        [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ]
    };
    let f = norm(eye.map(|x| -x));
    let r = norm(cross(f, [0.0, -1.0, 0.0]));
    let d = cross(f, r);
    let mut m = [[0.0; 4]; 4];
    for i in 0..3 {
        m[i] = [r[i], d[i], f[i], eye[i]];
    }
    m[3][3] = 1.0;
    Camera {
        fx: 1.1 * f64::from(W),
        fy: 1.1 * f64::from(W),
        cx: 0.5 * f64::from(W),
        cy: 0.5 * f64::from(H),
        width: W,
        height: H,
        world_from_camera: m,
    }
}

/// 40 opaque, differently coloured Gaussians in a cube of side 1.2 around the origin.
pub fn truth(rng: &mut SplitMix64) -> GaussianParams {
    let mut g = GaussianParams::default();
    let mut u = |lo: f64, hi: f64| (lo + (hi - lo) * rng.next_f64()) as f32;
    for _ in 0..40 {
        g.means.push([u(-0.6, 0.6), u(-0.6, 0.6), u(-0.6, 0.6)]);
        g.log_scales
            .push([u(-2.6, -1.9), u(-2.6, -1.9), u(-2.6, -1.9)]);
        g.quats
            .push([u(-1.0, 1.0), u(-1.0, 1.0), u(-1.0, 1.0), u(-1.0, 1.0)]);
        g.opacity_logits.push(u(1.0, 3.0));
        g.sh.extend([u(-1.5, 1.5), u(-1.5, 1.5), u(-1.5, 1.5)]);
    }
    g
}

pub fn render(ctx: &GpuContext, g: &GaussianParams, cams: &[Camera]) -> Vec<Vec<[f32; 3]>> {
    let views: Vec<View<'_>> = cams
        .iter()
        .map(|camera| View {
            gaussians: g,
            camera,
            background: [0.0; 3],
        })
        .collect();
    let batch = Batch::from_views(ctx, &views).unwrap();
    let renderer = Renderer::new(ctx);
    let state = renderer.forward(ctx, &batch).unwrap();
    let images = state.read_images(ctx, &batch).unwrap();
    images.into_iter().map(|i| i.color).collect()
}

pub fn to_float(color: &[[f32; 3]]) -> FloatImage {
    FloatImage {
        width: W,
        height: H,
        data: color.iter().flatten().map(|&v| f64::from(v)).collect(),
    }
}

pub fn mean_psnr(trainer: &mut Trainer<'_>, cams: &[Camera], targets: &[Vec<[f32; 3]>]) -> f64 {
    let total: f64 = cams
        .iter()
        .zip(targets)
        .map(|(cam, target)| {
            let img = trainer.render(cam).unwrap();
            psnr(&to_float(&img.color), &to_float(target))
        })
        .sum();
    total / cams.len() as f64
}

/// The truth, 8 training views and 4 held-out ones (every third of a ring of 12 at varying
/// heights), rendered by the engine.
pub struct Scene {
    pub truth: GaussianParams,
    pub train: Vec<TrainView>,
    pub test_cams: Vec<Camera>,
    pub test_images: Vec<Vec<[f32; 3]>>,
}

pub fn scene(ctx: &GpuContext, rng: &mut SplitMix64) -> Scene {
    let truth = truth(rng);
    let cams: Vec<Camera> = (0..12)
        .map(|i| {
            let a = f64::from(i) * std::f64::consts::TAU / 12.0;
            let y = 0.8 * (3.0 * a).sin();
            look_at_origin([3.0 * a.cos(), y, 3.0 * a.sin()])
        })
        .collect();
    let images = render(ctx, &truth, &cams);
    let (mut train, mut test_cams, mut test_images) = (Vec::new(), Vec::new(), Vec::new());
    for (i, (cam, image)) in cams.iter().zip(images).enumerate() {
        if i % 3 == 1 {
            test_cams.push(*cam);
            test_images.push(image);
        } else {
            train.push(TrainView {
                camera: *cam,
                image,
            });
        }
    }
    Scene {
        truth,
        train,
        test_cams,
        test_images,
    }
}

/// The "SfM" cloud: every `step`-th centre of the truth, jittered, with colours unrelated to
/// the truth, initialised by the INRIA rule.
pub fn noisy_init(truth: &GaussianParams, step: usize, rng: &mut SplitMix64) -> GaussianParams {
    let points: Vec<[f32; 3]> = truth
        .means
        .iter()
        .step_by(step)
        .map(|p| p.map(|v| v + (0.1 * (rng.next_f64() - 0.5)) as f32))
        .collect();
    let colors: Vec<[f32; 3]> = (0..points.len())
        .map(|_| std::array::from_fn(|_| rng.next_f64() as f32))
        .collect();
    init_from_points(&points, &colors).unwrap()
}
