//! Degenerate and non-finite inputs must neither crash the engine nor poison other
//! Gaussians: bad ones are culled (or, for zero scales, rendered as the low-pass dot) and
//! get finite gradients, everything else renders and differentiates as if they were absent.

mod common;

use cocog_engine::reference::{Gaussians64, render, render_backward};
use cocog_engine::{Batch, GaussianParams, Renderer, View};
use common::{gpu, random_scene, random_weights, test_camera};

fn poisoned_scene(cam: &cocog_engine::Camera) -> (GaussianParams, usize) {
    let mut g = random_scene(50, 2, 77, cam);
    let clean = g.len();
    let template = g.clone();
    let push = |g: &mut GaussianParams, edit: &dyn Fn(&mut GaussianParams, usize)| {
        let src = g.len() % clean;
        g.means.push(template.means[src]);
        g.log_scales.push(template.log_scales[src]);
        g.quats.push(template.quats[src]);
        g.opacity_logits.push(template.opacity_logits[src]);
        let stride = template.sh_stride();
        g.sh.extend_from_slice(&template.sh[src * stride..(src + 1) * stride]);
        let i = g.len() - 1;
        edit(g, i);
    };
    push(&mut g, &|g, i| g.means[i][0] = f32::NAN);
    push(&mut g, &|g, i| g.means[i][2] = f32::INFINITY);
    push(&mut g, &|g, i| g.quats[i] = [0.0; 4]);
    push(&mut g, &|g, i| g.quats[i][1] = f32::NAN);
    push(&mut g, &|g, i| g.log_scales[i] = [f32::NEG_INFINITY; 3]);
    push(&mut g, &|g, i| g.log_scales[i][1] = f32::INFINITY);
    push(&mut g, &|g, i| g.log_scales[i][0] = f32::NAN);
    push(&mut g, &|g, i| g.opacity_logits[i] = f32::NAN);
    push(&mut g, &|g, i| g.sh[i * 27 + 4] = f32::INFINITY);
    // Behind the camera, and exactly at its centre.
    let m = cam.world_from_camera;
    let behind: [f32; 3] = std::array::from_fn(|r| (m[r][3] - 2.0 * m[r][2]) as f32);
    let centre: [f32; 3] = std::array::from_fn(|r| m[r][3] as f32);
    push(&mut g, &|g, i| g.means[i] = behind);
    push(&mut g, &|g, i| g.means[i] = centre);
    (g, clean)
}

#[test]
fn non_finite_and_degenerate_gaussians_are_contained() {
    let Some(ctx) = gpu() else { return };
    let cam = test_camera(64, 48, 0.1);
    let (g, clean) = poisoned_scene(&cam);
    let renderer = Renderer::new(ctx);
    let view = View {
        gaussians: &g,
        camera: &cam,
        background: [0.3, 0.3, 0.3],
    };
    let batch = Batch::from_views(ctx, &[view]).unwrap();
    let state = renderer.forward(ctx, &batch).unwrap();
    let img = &state.read_images(ctx, &batch).unwrap()[0];
    let reference = render(&Gaussians64::from(&g), &cam, [0.3; 3]);
    for p in 0..img.color.len() {
        for k in 0..3 {
            assert!(img.color[p][k].is_finite(), "pixel {p} not finite");
            assert!(
                (f64::from(img.color[p][k]) - reference.color[p][k]).abs() < 1e-4,
                "pixel {p}: {:?} vs {:?}",
                img.color[p],
                reference.color[p]
            );
        }
        assert!(img.alpha[p].is_finite() && img.depth[p].is_finite());
    }

    let w = random_weights(64 * 48, 3);
    let v_rgba: Vec<[f32; 4]> =
        w.0.iter()
            .zip(&w.1)
            .map(|(c, &a)| [c[0] as f32, c[1] as f32, c[2] as f32, a as f32])
            .collect();
    let v_depth: Vec<f32> = w.2.iter().map(|&d| d as f32).collect();
    let grads = renderer.backward(
        ctx,
        &batch,
        &state,
        &ctx.storage_from("v_rgba", &v_rgba),
        Some(&ctx.storage_from("v_depth", &v_depth)),
    );
    let gpu_grads = grads.params.read_grads(ctx, 0, g.len() as u32).unwrap();
    assert!(
        gpu_grads.scalars().iter().all(|v| v.is_finite()),
        "a gradient is not finite"
    );
    let cpu = render_backward(&Gaussians64::from(&g), &cam, [0.3; 3], &w.0, &w.1, &w.2);
    for i in 0..clean {
        for k in 0..3 {
            let (a, b) = (f64::from(gpu_grads.v_means[i][k]), cpu.v_means[i][k]);
            assert!(
                (a - b).abs() <= 5e-3 * b.abs() + 1e-3,
                "Gaussian {i}: {a} vs {b}"
            );
        }
    }
    // Culled Gaussians get exactly zero; the zero-scale one (index clean + 4) is a valid dot.
    for i in (clean..g.len()).filter(|&i| i != clean + 4) {
        assert_eq!(
            gpu_grads.v_means[i], [0.0; 3],
            "culled Gaussian {i} got a gradient"
        );
        assert_eq!(gpu_grads.v_opacity_logits[i], 0.0);
    }
}

#[test]
fn empty_and_fully_culled_scenes_render_the_background() {
    let Some(ctx) = gpu() else { return };
    let cam = test_camera(20, 17, 0.0);
    let renderer = Renderer::new(ctx);
    let empty = GaussianParams::default();
    let (poisoned, clean) = poisoned_scene(&cam);
    let mut culled = poisoned.clone();
    // Keep only the non-finite/behind ones (drop the clean ones and the zero-scale dot).
    let keep: Vec<usize> = (clean..poisoned.len())
        .filter(|&i| i != clean + 4)
        .collect();
    culled.means = keep.iter().map(|&i| poisoned.means[i]).collect();
    culled.log_scales = keep.iter().map(|&i| poisoned.log_scales[i]).collect();
    culled.quats = keep.iter().map(|&i| poisoned.quats[i]).collect();
    culled.opacity_logits = keep.iter().map(|&i| poisoned.opacity_logits[i]).collect();
    let stride = poisoned.sh_stride();
    culled.sh = keep
        .iter()
        .flat_map(|&i| poisoned.sh[i * stride..(i + 1) * stride].to_vec())
        .collect();
    for g in [&empty, &culled] {
        let batch = Batch::from_views(
            ctx,
            &[View {
                gaussians: g,
                camera: &cam,
                background: [0.25, 0.5, 0.75],
            }],
        )
        .unwrap();
        let state = renderer.forward(ctx, &batch).unwrap();
        assert_eq!(state.num_intersections, 0);
        let img = &state.read_images(ctx, &batch).unwrap()[0];
        assert!(img.color.iter().all(|c| *c == [0.25, 0.5, 0.75]));
        assert!(img.alpha.iter().all(|&a| a == 0.0));
    }
}

/// A set whose SH buffer would exceed the adapter's buffer binding is refused with the count
/// that fits, where wgpu would panic when binding it. Runs where the limit is small enough to
/// reach with a few hundred MB of host memory (lavapipe: 128 MiB).
#[test]
fn a_set_wider_than_a_binding_is_refused_by_name() {
    let Some(ctx) = gpu() else { return };
    let limit = ctx.binding_limit();
    if limit > 256 << 20 {
        eprintln!("skipped: this adapter binds {} MiB", limit >> 20);
        return;
    }
    // SH degree 3: 192 bytes a Gaussian in the SH buffer.
    let n = (limit / 192 + 1) as usize;
    let g = GaussianParams {
        sh_degree: 3,
        means: vec![[0.0, 0.0, 2.0]; n],
        log_scales: vec![[-3.0; 3]; n],
        quats: vec![[1.0, 0.0, 0.0, 0.0]; n],
        opacity_logits: vec![0.0; n],
        sh: vec![0.0; n * 48],
    };
    let Err(e) = cocog_engine::ParamBuffers::upload(ctx, &[&g]) else {
        panic!("{n} Gaussians at SH 3 were uploaded past a {limit}-byte binding");
    };
    let msg = e.to_string();
    assert!(
        msg.contains(&format!("{n} Gaussians at SH degree 3"))
            && msg.contains(&format!("at most {} Gaussians fit", n - 1)),
        "{msg}"
    );
    // One fewer fits, and uploads.
    let mut fewer = g;
    fewer.means.pop();
    fewer.log_scales.pop();
    fewer.quats.pop();
    fewer.opacity_logits.pop();
    fewer.sh.truncate((n - 1) * 48);
    assert!(cocog_engine::ParamBuffers::upload(ctx, &[&fewer]).is_ok());
}
