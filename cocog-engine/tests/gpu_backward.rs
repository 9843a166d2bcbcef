//! GPU gradients against the analytic backward of the f64 reference (itself validated by
//! finite differences in reference_fd.rs), for both gradient-accumulation paths.

mod common;

use cocog_engine::reference::{Gaussians64, raster_backward, render_backward};
use cocog_engine::splat::MAX_SPLIT;
use cocog_engine::{
    Batch, Camera, GaussianParams, GpuContext, RasterBlocks, RasterSplit, Renderer, View,
};
use common::{gpu, random_scene, random_weights, scenes_per_camera, test_camera, views_of};

/// A GPU's default on frames of few tiles, named so that a `COCOG_RASTER_BLOCK` in the
/// environment does not change what the tests cover: the forward in 8×8 blocks, the backward
/// in whole tiles, reading the per-pixel state the forward wrote.
fn mixed(ctx: &GpuContext) -> Renderer {
    Renderer::new(ctx).with_raster_blocks(RasterBlocks {
        forward: 8,
        backward: 16,
    })
}

fn group_names(g: &GaussianParams) -> Vec<&'static str> {
    let n = g.len();
    let mut names = vec!["means"; 3 * n];
    names.extend(vec!["log_scales"; 3 * n]);
    names.extend(vec!["quats"; 4 * n]);
    names.extend(vec!["opacity_logits"; n]);
    names.extend(vec!["sh"; g.sh.len()]);
    names
}

/// Returns the chunks per tile list the backward walked (`RasterSplit`).
fn check(ctx: &GpuContext, renderer: &Renderer, views: &[View<'_>], seed: u64) -> u32 {
    check_with(ctx, renderer, views, seed, true)
}

/// `depth = false`: the loss has no depth term, so the backward runs without its depth channel
/// (`v_depth: None`) and the reference sees zero depth weights.
fn check_with(
    ctx: &GpuContext,
    renderer: &Renderer,
    views: &[View<'_>],
    seed: u64,
    depth: bool,
) -> u32 {
    let batch = Batch::from_views(ctx, views).unwrap();
    let state = renderer.forward(ctx, &batch).unwrap();
    let npix = (batch.width() * batch.height()) as usize;
    let weights: Vec<_> = (0..views.len())
        .map(|i| {
            let mut w = random_weights(npix, seed + i as u64);
            if !depth {
                w.2.fill(0.0);
            }
            w
        })
        .collect();
    let v_rgba: Vec<[f32; 4]> = weights
        .iter()
        .flat_map(|(c, a, _)| {
            c.iter()
                .zip(a)
                .map(|(c, &a)| [c[0] as f32, c[1] as f32, c[2] as f32, a as f32])
        })
        .collect();
    let v_depth: Vec<f32> = weights
        .iter()
        .flat_map(|(_, _, d)| d.iter().map(|&d| d as f32))
        .collect();
    let v_rgba = ctx.storage_from("v_rgba", &v_rgba);
    let v_depth = ctx.storage_from("v_depth", &v_depth);
    let grads = renderer.backward(ctx, &batch, &state, &v_rgba, depth.then_some(&*v_depth));
    for (i, view) in views.iter().enumerate() {
        let spec = batch.images[i];
        let gpu = grads
            .params
            .read_grads(ctx, spec.first, spec.count)
            .unwrap()
            .scalars();
        // The reference sees the f32 parameters widened, so both differentiate the same point.
        let g64 = Gaussians64::from(view.gaussians);
        let w = &weights[i];
        let bg = view.background.map(f64::from);
        let cpu = render_backward(&g64, view.camera, bg, &w.0, &w.1, &w.2).scalars();
        let names = group_names(view.gaussians);
        let v_proj_cpu = raster_backward(&g64, view.camera, bg, &w.0, &w.1, &w.2);
        let v_proj_gpu: Vec<[f32; 10]> = ctx
            .read_at(&grads.v_projected, spec.first as usize, spec.count as usize)
            .unwrap();
        let scale = v_proj_cpu
            .iter()
            .map(|v| v.v_mean2d[0].abs())
            .fold(0.0, f64::max);
        for (k, (gv, cv)) in v_proj_gpu.iter().zip(&v_proj_cpu).enumerate() {
            if !depth {
                assert_eq!(gv[9], 0.0, "v_depth[{k}] without a depth channel");
            }
            for (&a, &b) in gv[..2].iter().zip(&cv.v_mean2d) {
                let a = f64::from(a);
                assert!(
                    (a - b).abs() <= 5e-3 * b.abs() + 2e-4 * scale,
                    "v_mean2d[{k}]: {a} vs {b}"
                );
            }
        }
        assert_eq!(gpu.len(), cpu.len());
        for name in ["means", "log_scales", "quats", "opacity_logits", "sh"] {
            let idx: Vec<usize> = (0..cpu.len()).filter(|&k| names[k] == name).collect();
            let scale = idx.iter().map(|&k| cpu[k].abs()).fold(0.0, f64::max);
            assert!(scale > 0.0, "image {i}: {name} gradients are all zero");
            let mut worst = 0.0f64;
            for &k in &idx {
                // f32 atomics sum in arbitrary order: allow 0.5 % relative plus a floor tied
                // to the group's largest gradient.
                let err = (gpu[k] - cpu[k]).abs() / (5e-3 * cpu[k].abs() + 2e-4 * scale);
                worst = worst.max(err);
                assert!(
                    err <= 1.0,
                    "image {i} {name}[{k}]: GPU {} vs reference {}",
                    gpu[k],
                    cpu[k]
                );
            }
            eprintln!("image {i} {name}: worst error {worst:.2} of tolerance (scale {scale:.2e})");
        }
    }
    state.splits()
}

fn one_image(degree: u32, n: usize, seed: u64) -> (GaussianParams, Camera) {
    let cam = test_camera(64, 48, 0.15);
    (random_scene(n, degree, seed, &cam), cam)
}

#[test]
fn backward_matches_reference_every_sh_degree() {
    let Some(ctx) = gpu() else { return };
    let renderer = Renderer::new(ctx);
    for degree in 0..=3 {
        let (mut g, cam) = one_image(degree, 60, 40 + u64::from(degree));
        // A clamped (negative) colour channel has no gradient on either side.
        g.sh[0] = -4.0;
        let view = View {
            gaussians: &g,
            camera: &cam,
            background: [0.3, 0.2, 0.7],
        };
        check(ctx, &renderer, &[view], 90);
    }
}

#[test]
fn backward_without_subgroups_or_float_atomics_matches_reference() {
    let Some(ctx) = gpu() else { return };
    let renderer = Renderer::with_options(ctx, false, false);
    let (g, cam) = one_image(3, 50, 3);
    let view = View {
        gaussians: &g,
        camera: &cam,
        background: [0.0, 0.5, 1.0],
    };
    check(ctx, &renderer, &[view], 17);
}

#[test]
fn backward_compare_exchange_with_subgroups_matches_reference() {
    let Some(ctx) = gpu() else { return };
    let renderer = Renderer::with_options(ctx, false, true);
    let (g, cam) = one_image(2, 50, 4);
    let view = View {
        gaussians: &g,
        camera: &cam,
        background: [0.0, 0.5, 1.0],
    };
    check(ctx, &renderer, &[view], 18);
}

#[test]
fn batched_backward_keeps_images_apart() {
    let Some(ctx) = gpu() else { return };
    let renderer = Renderer::new(ctx);
    let (cams, sets) = scenes_per_camera(3, (40, 33), -0.1, 1, |_| 50, 60);
    let views = views_of(&cams, &sets, |i| [0.5, 0.1 * i as f32, 0.2]);
    check(ctx, &renderer, &views, 5);
}

#[test]
fn backward_without_the_depth_channel_matches_reference() {
    let Some(ctx) = gpu() else { return };
    // Both accumulation paths: native atomics and subgroup sums, compare-exchange per pixel.
    for (renderer, seed) in [
        (Renderer::new(ctx), 21),
        (Renderer::with_options(ctx, false, false), 22),
    ] {
        let (g, cam) = one_image(3, 60, seed);
        let view = View {
            gaussians: &g,
            camera: &cam,
            background: [0.3, 0.6, 0.1],
        };
        check_with(ctx, &renderer, &[view], seed + 100, false);
    }
}

/// The backward in 8×8 blocks of a tile (`RasterBlocks::both(8)`, forward too): both accumulation paths,
/// with and without the depth channel, then a batch of frames whose sides are multiples of
/// neither 8 nor 16.
#[test]
fn backward_in_8x8_blocks_matches_reference() {
    let Some(ctx) = gpu() else { return };
    for (renderer, seed, depth) in [
        (
            Renderer::new(ctx).with_raster_blocks(RasterBlocks::both(8)),
            31,
            true,
        ),
        (
            Renderer::new(ctx).with_raster_blocks(RasterBlocks::both(8)),
            32,
            false,
        ),
        (
            Renderer::with_options(ctx, false, false).with_raster_blocks(RasterBlocks::both(8)),
            33,
            true,
        ),
    ] {
        let (g, cam) = one_image(3, 60, seed);
        let view = View {
            gaussians: &g,
            camera: &cam,
            background: [0.2, 0.4, 0.9],
        };
        check_with(ctx, &renderer, &[view], seed + 100, depth);
    }
    let renderer = Renderer::new(ctx).with_raster_blocks(RasterBlocks::both(8));
    let (cams, sets) = scenes_per_camera(2, (45, 37), 0.1, 2, |_| 50, 70);
    let views = views_of(&cams, &sets, |i| [0.1, 0.3 * i as f32, 0.6]);
    check(ctx, &renderer, &views, 41);
}

/// The backward with each tile's list walked in chunks, a workgroup each
/// (`with_raster_split`): chunks of a few Gaussians, so most pixels start a chunk from the
/// state the forward recorded at its end; both accumulation paths, with and without depth, in
/// 16×16 tiles and 8×8 blocks; then a dense scene whose pixels run out of transmittance before,
/// inside and after chunk boundaries; a sparse one with empty tiles and lists shorter than the
/// split; and ragged frames in a batch.
#[test]
fn backward_in_chunks_matches_reference() {
    let Some(ctx) = gpu() else { return };
    for (renderer, split, seed, depth) in [
        (mixed(ctx), 2, 51, true),
        (mixed(ctx), 5, 52, false),
        (Renderer::with_options(ctx, false, false), 3, 53, true),
        (
            Renderer::new(ctx).with_raster_blocks(RasterBlocks::both(8)),
            4,
            54,
            true,
        ),
        (
            Renderer::new(ctx).with_raster_blocks(RasterBlocks::both(16)),
            3,
            58,
            false,
        ),
    ] {
        let renderer = renderer.with_raster_split(RasterSplit::Fixed(split));
        let (g, cam) = one_image(3, 60, seed);
        let view = View {
            gaussians: &g,
            camera: &cam,
            background: [0.6, 0.3, 0.2],
        };
        assert_eq!(
            check_with(ctx, &renderer, &[view], seed + 100, depth),
            split
        );
    }
    let (mut g, cam) = one_image(1, 300, 55);
    for o in &mut g.opacity_logits {
        *o += 3.0;
    }
    let view = View {
        gaussians: &g,
        camera: &cam,
        background: [1.0, 1.0, 1.0],
    };
    for renderer in [
        mixed(ctx),
        Renderer::new(ctx).with_raster_blocks(RasterBlocks::both(16)),
    ] {
        let renderer = renderer.with_raster_split(RasterSplit::Fixed(7));
        assert_eq!(check(ctx, &renderer, &[view], 155), 7);
    }
    let renderer = Renderer::new(ctx).with_raster_split(RasterSplit::Fixed(4));
    let (g, cam) = one_image(1, 6, 56);
    let view = View {
        gaussians: &g,
        camera: &cam,
        background: [0.3, 0.6, 0.9],
    };
    assert_eq!(check(ctx, &renderer, &[view], 156), 4);
    let renderer = Renderer::new(ctx)
        .with_raster_blocks(RasterBlocks::both(8))
        .with_raster_split(RasterSplit::Fixed(5));
    let (cams, sets) = scenes_per_camera(2, (45, 37), 0.1, 2, |_| 80, 57);
    let views = views_of(&cams, &sets, |i| [0.1, 0.3 * i as f32, 0.6]);
    assert_eq!(check(ctx, &renderer, &views, 157), 5);
}

/// Chunks of hundreds of Gaussians, each walked in several batches (as on real captures), in
/// 16×16 tiles and 8×8 blocks, both accumulation paths; then `RasterSplit::Auto` on the same
/// kind of scene, which splits a small frame into `MAX_SPLIT` chunks of at least
/// `AUTO_MIN_CHUNK`.
#[test]
fn backward_in_long_chunks_matches_reference() {
    let Some(ctx) = gpu() else { return };
    for (renderer, split, n, shift, seed) in [
        (mixed(ctx), 2, 4000, -3.0, 61),
        (mixed(ctx), 3, 4000, 0.0, 62),
        (
            Renderer::new(ctx).with_raster_blocks(RasterBlocks::both(16)),
            2,
            4000,
            -3.0,
            66,
        ),
        (
            Renderer::new(ctx).with_raster_blocks(RasterBlocks::both(8)),
            2,
            3000,
            -2.0,
            63,
        ),
        (Renderer::with_options(ctx, false, false), 2, 4000, -3.0, 64),
        (mixed(ctx), 0, 3000, -2.0, 65),
    ] {
        let renderer = renderer.with_raster_split(if split == 0 {
            RasterSplit::Auto
        } else {
            RasterSplit::Fixed(split)
        });
        let (mut g, cam) = one_image(1, n, seed);
        // Fainter Gaussians: lists stay long before transmittance runs out.
        for o in &mut g.opacity_logits {
            *o += shift;
        }
        let view = View {
            gaussians: &g,
            camera: &cam,
            background: [0.3, 0.6, 0.9],
        };
        let expected = if split == 0 { MAX_SPLIT } else { split };
        assert_eq!(check(ctx, &renderer, &[view], seed + 100), expected);
    }
}
