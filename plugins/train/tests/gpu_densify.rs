//! Density control on the GPU: the statistics kernel against a CPU model of INRIA's
//! `add_densification_stats`, and a training run that densifies, resets opacities and still
//! fits held-out views.

mod common;

use cocog_engine::{Batch, ImageLoss, Renderer, View, Workspace};
use cocog_train::{DensifyConfig, GradStats, SplitMix64, TrainConfig, Trainer};
use common::*;

#[test]
fn gradient_statistics_match_a_cpu_model() {
    let Some(ctx) = gpu() else { return };
    let mut rng = SplitMix64::new(21);
    let s = scene(ctx, &mut rng);
    let start = noisy_init(&s.truth, 1, &mut rng);
    let renderer = Renderer::new(ctx);
    let loss = ImageLoss::new(ctx);
    let n = start.len();
    let stats = GradStats::new(ctx, n as u32);
    let (mut accum, mut denom) = (vec![0.0f64; n], vec![0u32; n]);
    for view in &s.train[..3] {
        let batch = Batch::from_views(
            ctx,
            &[View {
                gaussians: &start,
                camera: &view.camera,
                background: [0.0; 3],
            }],
        )
        .unwrap();
        let rgba: Vec<[f32; 4]> = view.image.iter().map(|c| [c[0], c[1], c[2], 1.0]).collect();
        let target = ctx.storage_from("target", &rgba);
        let state = renderer.forward(ctx, &batch).unwrap();
        let mut rec = ctx.recorder();
        let out = loss.compute(
            &mut rec,
            &mut Workspace::default(),
            &state.rgba,
            &target,
            W,
            H,
            1,
            0.2,
        );
        rec.submit();
        let v_depth = ctx.storage("v_depth", u64::from(W * H) * 4);
        let grads = renderer.backward(ctx, &batch, &state, &out.v_pred, &v_depth);
        let mut rec = ctx.recorder();
        stats.accumulate(&mut rec, &state, &grads, W, H);
        rec.submit();
        // A pass flagged as overflowed (a skipped step) must add nothing. The write lands
        // before the next submission, after the one above.
        ctx.queue
            .write_buffer(&state.status, 0, bytemuck::cast_slice(&[1u32, 0]));
        let mut skipped = ctx.recorder();
        stats.accumulate(&mut skipped, &state, &grads, W, H);
        skipped.submit();
        // The CPU model: visible ⇔ radius > 0; norm of the pixel gradient scaled to NDC.
        let projected: Vec<f32> = ctx.read(&state.projected, 12 * n).unwrap();
        let v_proj: Vec<f32> = ctx.read(&grads.v_projected, 10 * n).unwrap();
        for i in 0..n {
            if projected[12 * i + 7] > 0.0 {
                let gx = f64::from(v_proj[10 * i]) * f64::from(W) / 2.0;
                let gy = f64::from(v_proj[10 * i + 1]) * f64::from(H) / 2.0;
                accum[i] += gx.hypot(gy);
                denom[i] += 1;
            }
        }
    }
    let got = stats.read_mean(ctx).unwrap();
    let mut visible = 0;
    for i in 0..n {
        let want = if denom[i] > 0 {
            visible += 1;
            accum[i] / f64::from(denom[i])
        } else {
            0.0
        };
        let err = (f64::from(got[i]) - want).abs();
        assert!(
            err <= 1e-5 * want.abs() + 1e-9,
            "Gaussian {i}: {} vs {want}",
            got[i]
        );
    }
    assert!(
        visible > n / 2,
        "only {visible} of {n} Gaussians were ever visible"
    );
    assert!(
        got.iter().any(|&v| v > 2e-4),
        "no Gaussian reaches the threshold: {got:?}"
    );
}

#[test]
fn densifying_from_a_sparse_cloud_grows_the_set_and_fits_held_out_views() {
    let Some(ctx) = gpu() else { return };
    let mut rng = SplitMix64::new(5);
    let s = scene(ctx, &mut rng);
    // Every fourth centre only: the missing Gaussians must come from densification.
    let init = noisy_init(&s.truth, 4, &mut rng);
    // 400 iterations after the opacity reset at 300: with 200 the held-out gain fell between
    // 4.7 and 6.4 dB from run to run (float atomics sum in any order and the run is chaotic),
    // and on one CI machine below the 5 dB asked for. With 400 it measured 6.4-8.6 dB over
    // six runs; the same run without densification gains 3.1 dB.
    let densify = DensifyConfig {
        from_iter: 50,
        until_iter: 450,
        interval: 50,
        opacity_reset_interval: 300,
        ..DensifyConfig::default()
    };
    let config = TrainConfig {
        iterations: 700,
        max_sh_degree: 0,
        seed: 3,
        loss_every: 0,
        densify: Some(densify),
        ..TrainConfig::default()
    };
    let mut trainer = Trainer::new(ctx, &init, &s.train, config).unwrap();
    let before = mean_psnr(&mut trainer, &s.test_cams, &s.test_images);
    let mut counts = Vec::new();
    for it in 1..=700 {
        let stats = trainer.step().unwrap();
        if it % 50 == 0 {
            counts.push(stats.num_gaussians);
        }
        if it == 300 {
            let g = trainer.gaussians().unwrap();
            assert_eq!(g.len() as u32, stats.num_gaussians);
            let cap = cocog_train::inverse_sigmoid(0.01) + 1e-6;
            assert!(g.opacity_logits.iter().all(|&l| l <= cap), "opacity reset");
        }
    }
    let after = mean_psnr(&mut trainer, &s.test_cams, &s.test_images);
    eprintln!("Gaussians every 50 its {counts:?}; held-out PSNR {before:.2} → {after:.2} dB");
    assert!(
        *counts.iter().max().unwrap() > 2 * init.len() as u32,
        "{counts:?}"
    );
    assert!(
        after > before + 5.0,
        "PSNR only went from {before} to {after}"
    );
    trainer.gaussians().unwrap().validate().unwrap();
}
