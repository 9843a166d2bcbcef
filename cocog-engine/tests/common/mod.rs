//! Shared helpers for the engine's integration tests: a seeded RNG, tiny scenes, cameras.
#![allow(dead_code)]

use cocog_engine::{Camera, GaussianParams, View, sh_coeffs_per_channel};

/// cocog's seeded generator with the ranges the tests draw from.
pub struct Rng(cocog_formats::rng::SplitMix64);

impl Rng {
    pub fn new(seed: u64) -> Self {
        Self(cocog_formats::rng::SplitMix64::new(seed))
    }

    pub fn next_u64(&mut self) -> u64 {
        self.0.next_u64()
    }

    /// Uniform in [lo, hi).
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.0.next_f64()
    }

    pub fn range_f32(&mut self, lo: f64, hi: f64) -> f32 {
        self.range(lo, hi) as f32
    }
}

/// A camera with a non-trivial pose: rotated about y and x, translated off the origin.
pub fn test_camera(width: u32, height: u32, yaw: f64) -> Camera {
    let (sy, cy) = yaw.sin_cos();
    let (sx, cx) = 0.1f64.sin_cos();
    // world_from_camera rotation = Ry(yaw) · Rx(0.1).
    let ry = [[cy, 0.0, sy], [0.0, 1.0, 0.0], [-sy, 0.0, cy]];
    let rx = [[1.0, 0.0, 0.0], [0.0, cx, -sx], [0.0, sx, cx]];
    let mut m = [[0.0; 4]; 4];
    for i in 0..3 {
        for j in 0..3 {
            m[i][j] = (0..3).map(|k| ry[i][k] * rx[k][j]).sum();
        }
    }
    m[0][3] = 0.2;
    m[1][3] = -0.1;
    m[2][3] = -0.3;
    m[3][3] = 1.0;
    Camera {
        fx: 0.9 * f64::from(width),
        fy: 0.95 * f64::from(width),
        cx: 0.5 * f64::from(width) + 0.7,
        cy: 0.5 * f64::from(height) - 0.4,
        width,
        height,
        world_from_camera: m,
    }
}

/// `n` random Gaussians placed in front of `cam` (about 1.5–4 units away), mostly on screen.
pub fn random_scene(n: usize, sh_degree: u32, seed: u64, cam: &Camera) -> GaussianParams {
    let mut rng = Rng::new(seed);
    let m = cam.world_from_camera;
    let coeffs = sh_coeffs_per_channel(sh_degree);
    let mut g = GaussianParams {
        sh_degree,
        ..Default::default()
    };
    for _ in 0..n {
        let z = rng.range(1.5, 4.0);
        let x = z * (rng.range(0.0, f64::from(cam.width)) - cam.cx) / cam.fx;
        let y = z * (rng.range(0.0, f64::from(cam.height)) - cam.cy) / cam.fy;
        let p = [x, y, z];
        let world: [f32; 3] = std::array::from_fn(|r| {
            (m[r][0] * p[0] + m[r][1] * p[1] + m[r][2] * p[2] + m[r][3]) as f32
        });
        g.means.push(world);
        g.log_scales
            .push(std::array::from_fn(|_| rng.range_f32(-3.2, -1.6)));
        g.quats
            .push(std::array::from_fn(|_| rng.range_f32(-1.0, 1.0)));
        g.opacity_logits.push(rng.range_f32(-1.5, 2.5));
        for _ in 0..3 {
            g.sh.push(rng.range_f32(-1.0, 1.5));
            for _ in 1..coeffs {
                g.sh.push(rng.range_f32(-0.3, 0.3));
            }
        }
    }
    g
}

/// Random per-pixel loss weights: (colour, alpha, depth).
pub fn random_weights(npix: usize, seed: u64) -> (Vec<[f64; 3]>, Vec<f64>, Vec<f64>) {
    let mut rng = Rng::new(seed);
    let c = (0..npix)
        .map(|_| std::array::from_fn(|_| rng.range(-1.0, 1.0)))
        .collect();
    let a = (0..npix).map(|_| rng.range(-1.0, 1.0)).collect();
    let d = (0..npix).map(|_| rng.range(-0.3, 0.3)).collect();
    (c, a, d)
}

#[allow(unused_imports)] // not every test binary that includes this module runs on the GPU
pub use cocog_engine::test_gpu as gpu;

/// Runs `gemm` once on a plain problem's operands (its prelude binds A at 2, B at 3 and C at 4)
/// and reads back `outputs` × M × N values of C.
pub fn run_gemm(
    ctx: &cocog_engine::GpuContext,
    gemm: &cocog_engine::Gemm,
    shape: cocog_engine::GemmShape,
    a: &[f32],
    b: &[f32],
    outputs: usize,
) -> Vec<f32> {
    let len = outputs * shape.m as usize * shape.n as usize;
    let (ga, gb) = (ctx.storage_from("a", a), ctx.storage_from("b", b));
    let gc = ctx.storage("c", (len * 4) as u64);
    let mut ws = cocog_engine::Workspace::default();
    let mut rec = ctx.recorder();
    gemm.encode(&mut rec, &mut ws, shape, &[(2, &ga), (3, &gb), (4, &gc)]);
    rec.submit();
    ctx.read(&gc, len).expect("read C")
}

/// `frames` cameras of `width`×`height`, each yawed `yaw_step` from the last, and in front of
/// camera i a random scene of `count(i)` Gaussians at SH `degree` from seed `seed + i`.
pub fn scenes_per_camera(
    frames: usize,
    (width, height): (u32, u32),
    yaw_step: f64,
    degree: u32,
    count: impl Fn(usize) -> usize,
    seed: u64,
) -> (Vec<Camera>, Vec<GaussianParams>) {
    let cams: Vec<Camera> = (0..frames)
        .map(|i| test_camera(width, height, yaw_step * i as f64))
        .collect();
    let sets = (0..frames)
        .map(|i| random_scene(count(i), degree, seed + i as u64, &cams[i]))
        .collect();
    (cams, sets)
}

/// One view per camera and its scene, on background `background(i)`.
pub fn views_of<'a>(
    cams: &'a [Camera],
    sets: &'a [GaussianParams],
    background: impl Fn(usize) -> [f32; 3],
) -> Vec<View<'a>> {
    (0..cams.len())
        .map(|i| View {
            gaussians: &sets[i],
            camera: &cams[i],
            background: background(i),
        })
        .collect()
}

/// A plain product's problem for the GEMM kernels: A (M×K) and B (K×N), each stored contiguous
/// along K or not as `layout` says, bound at 2 and 3; C = A·B + `offset` lands row-major at 4.
/// With split K every batch sums into one C.
pub fn plain_gemm_problem(layout: cocog_engine::GemmLayout, offset: f32) -> String {
    let a = if layout.a_k_fast {
        "a[(bt * gemm.m + m) * gemm.k + k]"
    } else {
        "a[(bt * gemm.k + k) * gemm.m + m]"
    };
    let b = if layout.b_k_fast {
        "b[(bt * gemm.n + n) * gemm.k + k]"
    } else {
        "b[(bt * gemm.k + k) * gemm.n + n]"
    };
    format!(
        "@group(0) @binding(2) var<storage, read> a: array<f32>;\n\
         @group(0) @binding(3) var<storage, read> b: array<f32>;\n\
         @group(0) @binding(4) var<storage, read_write> c: array<f32>;\n\
         fn load_a(bt: u32, m: u32, k: u32) -> f32 {{ return {a}; }}\n\
         fn load_b(bt: u32, k: u32, n: u32) -> f32 {{ return {b}; }}\n\
         fn epilogue(bt: u32, m: u32, n: u32, v: f32) {{ c[(bt * gemm.m + m) * gemm.n + n] = v + {offset:?}; }}\n"
    )
}
