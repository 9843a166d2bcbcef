//! Forward/backward throughput of the engine on a synthetic scene.
//!
//! `cargo bench -p cocog-engine`; sized by env vars (defaults in brackets):
//! COCOG_BENCH_GAUSSIANS [20000], COCOG_BENCH_WIDTH [320], COCOG_BENCH_HEIGHT [240],
//! COCOG_BENCH_IMAGES [1] (batched images, each with its own Gaussian set),
//! COCOG_BENCH_SH [3], COCOG_BENCH_ITERS [10]. COCOG_ADAPTER picks the adapter.

use std::time::Instant;

mod common;

use cocog_engine::{
    Batch, Camera, GaussianParams, GpuContext, Renderer, View, sh_coeffs_per_channel,
};
use common::{env, noise};

fn scene(n: usize, degree: u32, seed: u64, cam: &Camera) -> GaussianParams {
    let mut s = seed;
    let coeffs = 3 * sh_coeffs_per_channel(degree);
    let mut g = GaussianParams {
        sh_degree: degree,
        ..Default::default()
    };
    for _ in 0..n {
        let z = 2.0 + 6.0 * noise(&mut s);
        let x = z * (noise(&mut s) * cam.width as f32 - cam.cx as f32) / cam.fx as f32;
        let y = z * (noise(&mut s) * cam.height as f32 - cam.cy as f32) / cam.fy as f32;
        g.means.push([x, y, z]);
        g.log_scales
            .push(std::array::from_fn(|_| -4.5 + 2.0 * noise(&mut s)));
        g.quats.push(std::array::from_fn(|_| noise(&mut s) - 0.5));
        g.opacity_logits.push(4.0 * noise(&mut s) - 2.0);
        g.sh.extend((0..coeffs).map(|_| noise(&mut s) - 0.5));
    }
    g
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let n = env("COCOG_BENCH_GAUSSIANS", 20_000) as usize;
    let (w, h) = (
        env("COCOG_BENCH_WIDTH", 320) as u32,
        env("COCOG_BENCH_HEIGHT", 240) as u32,
    );
    let images = env("COCOG_BENCH_IMAGES", 1) as usize;
    let degree = env("COCOG_BENCH_SH", 3) as u32;
    let iters = env("COCOG_BENCH_ITERS", 10).max(1);

    let ctx = GpuContext::new()?;
    let renderer = Renderer::new(&ctx);
    let mut identity = [[0.0; 4]; 4];
    (0..4).for_each(|i| identity[i][i] = 1.0);
    let cam = Camera {
        fx: f64::from(w),
        fy: f64::from(w),
        cx: f64::from(w) / 2.0,
        cy: f64::from(h) / 2.0,
        width: w,
        height: h,
        world_from_camera: identity,
    };
    let sets: Vec<GaussianParams> = (0..images)
        .map(|i| scene(n, degree, i as u64, &cam))
        .collect();
    let views: Vec<View<'_>> = sets
        .iter()
        .map(|g| View {
            gaussians: g,
            camera: &cam,
            background: [0.0; 3],
        })
        .collect();
    let batch = Batch::from_views(&ctx, &views)?;
    let pixels = (w * h) as usize * images;
    let v_rgba = ctx.storage_from("v_rgba", &vec![[1e-3f32; 4]; pixels]);
    let v_depth = ctx.storage_from("v_depth", &vec![1e-4f32; pixels]);
    ctx.memory.reset_peak();

    let (mut fwd_s, mut bwd_s, mut intersections) = (0.0, 0.0, 0);
    // One untimed warm-up iteration (pipeline caches, allocator).
    for it in 0..=iters {
        let t0 = Instant::now();
        let state = renderer.forward(&ctx, &batch)?;
        ctx.wait()?;
        let t1 = Instant::now();
        let grads = renderer.backward(&ctx, &batch, &state, &v_rgba, Some(&v_depth));
        ctx.wait()?;
        let t2 = Instant::now();
        drop(grads);
        if it > 0 {
            fwd_s += (t1 - t0).as_secs_f64();
            bwd_s += (t2 - t1).as_secs_f64();
        }
        intersections = state.num_intersections;
    }
    let k = iters as f64;
    println!("adapter: {}", ctx.adapter_name());
    println!(
        "scene: {images} image(s) of {w}x{h}, {n} Gaussians each (SH degree {degree}), {intersections} tile intersections"
    );
    println!("forward:  {:.2} ms", 1e3 * fwd_s / k);
    println!("backward: {:.2} ms", 1e3 * bwd_s / k);
    println!(
        "train step (forward + backward): {:.2} it/s",
        k / (fwd_s + bwd_s)
    );
    println!(
        "peak GPU buffer memory allocated by the engine: {:.1} MiB",
        ctx.memory.peak_bytes() as f64 / (1 << 20) as f64
    );
    Ok(())
}
