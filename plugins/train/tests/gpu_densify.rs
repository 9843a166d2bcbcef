//! Density control on the GPU: the statistics kernel against a CPU model of INRIA's
//! `add_densification_stats`, the GPU densification against the CPU rule it replaces, and a
//! training run that densifies, resets opacities and still fits held-out views.

mod common;

use cocog_engine::{Batch, GaussianParams, ImageLoss, ParamBuffers, Renderer, View, Workspace};
use cocog_train::{
    BURIED_LOG_SCALE, BURIED_OPACITY_LOGIT, DensifyConfig, DensifyInputs, DepthAxis, GpuDensify,
    GradStats, SplitMix64, SplitNoise, TrainConfig, Trainer, apply_plan, gather_rows, plan_densify,
};
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
        let out = loss
            .compute(
                &mut rec,
                &mut Workspace::default(),
                &state.rgba,
                &target,
                W,
                H,
                1,
                0.2,
            )
            .expect("loss");
        rec.submit();
        let grads = renderer.backward(ctx, &batch, &state, &out.v_pred, None);
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
        // Mid-interval, when a densification's count has arrived.
        if it % 50 == 25 {
            counts.push(stats.num_gaussians);
        }
        if it == 300 {
            // Densification at 300 too: its count arrives a few steps later, and until then
            // the step trains up to twice the old count, the extra rows buried.
            let g = trainer.gaussians().unwrap();
            assert!(g.len() as u32 <= stats.num_gaussians);
            let cap = cocog_train::inverse_sigmoid(0.01) + 1e-6;
            assert!(g.opacity_logits.iter().all(|&l| l <= cap), "opacity reset");
        }
    }
    let after = mean_psnr(&mut trainer, &s.test_cams, &s.test_images);
    eprintln!("Gaussians at 25, 75, … {counts:?}; held-out PSNR {before:.2} → {after:.2} dB");
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

/// A set where every branch of the rule is taken: about half the Gaussians hot, scales on both
/// sides of the clone/split boundary (0.01 here) and of the large-prune one (0.1), opacities
/// on both sides of the (depth-weighted) 0.005 threshold, rotations and SH of degree 1, and
/// row `n..2n` junk that densification must overwrite or leave alone.
fn random_case(n: usize, rng: &mut SplitMix64) -> (GaussianParams, Vec<f32>, Vec<f32>) {
    let mut u = |lo: f64, hi: f64| (lo + (hi - lo) * rng.next_f64()) as f32;
    let mut g = GaussianParams {
        sh_degree: 1,
        ..Default::default()
    };
    let (mut accum, mut denom) = (Vec::new(), Vec::new());
    for i in 0..2 * n {
        let junk = i >= n;
        g.means.push(if junk {
            [1e6; 3]
        } else {
            [u(-1.0, 1.0), u(-1.0, 1.0), u(0.5, 3.0)]
        });
        let size = u(-6.5, -1.5);
        g.log_scales.push([
            size + u(-0.5, 0.5),
            size + u(-0.5, 0.5),
            size + u(-0.5, 0.5),
        ]);
        g.quats
            .push([u(-1.0, 1.0), u(-1.0, 1.0), u(-1.0, 1.0), u(-1.0, 1.0)]);
        // Opacity from 0.0007 to 0.05.
        g.opacity_logits.push(u(-7.3, -3.0));
        g.sh.extend((0..12).map(|_| u(-1.0, 1.0)));
        let views = (u(0.0, 4.0) as u32) as f32;
        denom.push(views);
        accum.push(views * u(0.0, 4e-4));
    }
    (g, accum, denom)
}

#[test]
fn gpu_densification_makes_the_cpu_rules_decisions() {
    let Some(ctx) = gpu() else { return };
    let n = 700;
    let mut rng = SplitMix64::new(77);
    let (g, accum, denom) = random_case(n, &mut rng);
    let moments: Vec<(Vec<f32>, u32)> = [3u32, 3, 3, 3, 4, 4, 1, 1, 12, 12]
        .iter()
        .map(|&stride| {
            let len = 2 * n * stride as usize;
            ((0..len).map(|_| rng.next_f64() as f32).collect(), stride)
        })
        .collect();
    let axes = [
        (3.0, Some([0.1, -0.2, 0.97]), false),
        (2.0, None, true),
        (1.0, Some([0.0, 0.0, 1.0]), true),
    ];
    let densify = GpuDensify::new(ctx);
    for (case, (range, forward, prune_large)) in axes.into_iter().enumerate() {
        let config = DensifyConfig {
            depth_prune_range: range,
            ..DensifyConfig::default()
        };
        let forward = forward.map(|f: [f64; 3]| {
            let l = f.iter().map(|v| v * v).sum::<f64>().sqrt();
            f.map(|v| v / l)
        });
        let axis = DepthAxis {
            origin: [0.05, -0.1, -0.5],
            forward,
        };
        let noise = SplitNoise {
            seed: 0x1234_5678_9abc_def0,
            iteration: 600 + case as u32,
        };
        let mut params = ParamBuffers::upload(ctx, &[&g]).unwrap();
        params.num_gaussians = n as u32;
        let accum_gpu = ctx.storage_from("accum", &accum);
        let denom_gpu = ctx.storage_from("denom", &denom);
        let moment_gpu: Vec<(cocog_engine::GpuBuffer, u32)> = moments
            .iter()
            .map(|(m, s)| (ctx.storage_from("moment", m), *s))
            .collect();
        let moment_refs: Vec<(&cocog_engine::GpuBuffer, u32)> =
            moment_gpu.iter().map(|(b, s)| (b, *s)).collect();
        let inputs = DensifyInputs {
            config: &config,
            scale: 1.0,
            prune_large,
            noise,
            axis: &axis,
            accum: &accum_gpu,
            denom: &denom_gpu,
            moments: &moment_refs,
        };
        let mut ws = Workspace::default();
        let mut rec = ctx.recorder();
        let recorded = densify.record(&mut rec, &mut ws, &params, &inputs);
        rec.submit();
        let counts: Vec<u32> = ctx.read(&recorded.counts, 4).unwrap();

        // The oracle: the CPU rule on the first n rows.
        let live = GaussianParams {
            sh_degree: 1,
            means: g.means[..n].to_vec(),
            log_scales: g.log_scales[..n].to_vec(),
            quats: g.quats[..n].to_vec(),
            opacity_logits: g.opacity_logits[..n].to_vec(),
            sh: g.sh[..12 * n].to_vec(),
        };
        let mean_grads: Vec<f32> = (0..n)
            .map(|i| {
                if denom[i] > 0.0 {
                    accum[i] / denom[i]
                } else {
                    0.0
                }
            })
            .collect();
        let plan = plan_densify(
            &live,
            &mean_grads,
            1.0,
            prune_large,
            &config,
            &noise,
            Some(&axis),
        );
        let want = apply_plan(&live, &plan);
        eprintln!(
            "case {case}: {n} → {} Gaussians ({} cloned, {} split, {} pruned)",
            plan.origins.len(),
            plan.cloned,
            plan.split,
            plan.pruned
        );
        assert!(
            plan.cloned > 20 && plan.split > 20 && plan.pruned > 20,
            "case {case} misses a branch"
        );
        let kept = n - plan.split;
        assert_eq!(
            counts,
            [
                plan.origins.len() as u32,
                kept as u32,
                plan.cloned as u32,
                plan.split as u32
            ],
            "case {case}: [after, kept, cloned, split]"
        );
        let r = params.read_grads(ctx, 0, counts[0]).unwrap();
        let got = GaussianParams {
            sh_degree: 1,
            means: r.v_means,
            log_scales: r.v_log_scales,
            quats: r.v_quats,
            opacity_logits: r.v_opacity_logits,
            sh: r.v_sh,
        };
        // Split children's means come from f32 normals on the GPU and f64 ones here.
        for (k, (a, b)) in got.means.iter().zip(&want.means).enumerate() {
            for c in 0..3 {
                assert!(
                    (a[c] - b[c]).abs() <= 1e-5 * (1.0 + b[c].abs()),
                    "case {case}: mean {k}.{c}: {} vs {}",
                    a[c],
                    b[c]
                );
            }
        }
        for (k, (a, b)) in got.log_scales.iter().zip(&want.log_scales).enumerate() {
            for c in 0..3 {
                assert!(
                    (a[c] - b[c]).abs() <= 1e-5,
                    "case {case}: log-scale {k}.{c}: {} vs {}",
                    a[c],
                    b[c]
                );
            }
        }
        assert_eq!(got.quats, want.quats, "case {case}: quaternions");
        assert_eq!(got.opacity_logits, want.opacity_logits, "case {case}");
        assert_eq!(got.sh, want.sh, "case {case}: SH");
        for (j, ((buffer, stride), (data, _))) in moment_gpu.iter().zip(&moments).enumerate() {
            let stride = *stride as usize;
            let live = &data[..n * stride];
            let want = gather_rows(live, stride, &plan.origins, true);
            let got: Vec<f32> = ctx.read(buffer, 2 * n * stride).unwrap();
            let (live, buried) = got.split_at(want.len());
            assert_eq!(live, want, "case {case}: moment buffer {j}");
            assert!(
                buried.iter().all(|&v| v == 0.0),
                "case {case}: buried moments {j}"
            );
        }
        // Rows past the new count up to 2n are finite and draw nothing.
        let after = counts[0] as usize;
        params.num_gaussians = 2 * n as u32;
        let buried = params.read_grads(ctx, 0, 2 * n as u32).unwrap();
        assert!(buried.v_means[after..].iter().all(|m| *m == [0.0; 3]));
        assert!(
            buried.v_log_scales[after..]
                .iter()
                .all(|l| *l == [BURIED_LOG_SCALE; 3])
        );
        assert!(
            buried.v_quats[after..]
                .iter()
                .all(|q| *q == [1.0, 0.0, 0.0, 0.0])
        );
        assert!(
            buried.v_opacity_logits[after..]
                .iter()
                .all(|&l| l == BURIED_OPACITY_LOGIT && 255.0 / (1.0 + (-l).exp()) < 1.0),
            "case {case}: buried opacities"
        );
        assert!(buried.v_sh[12 * after..].iter().all(|&v| v == 0.0));
    }
}

/// `iterations` at SH 0 from seed 4, densifying every `[from, until, interval]` at a quarter
/// of INRIA's gradient threshold (most of the sparse start clones or splits), with opacity
/// resets every `reset` (0: none).
fn eager(iterations: u32, [from, until, interval]: [u32; 3], reset: u32) -> TrainConfig {
    TrainConfig {
        iterations,
        max_sh_degree: 0,
        seed: 4,
        loss_every: 0,
        densify: Some(DensifyConfig {
            from_iter: from,
            until_iter: until,
            interval,
            opacity_reset_interval: reset,
            grad_threshold: 5e-5,
            ..DensifyConfig::default()
        }),
        ..TrainConfig::default()
    }
}

/// The trainer's CPU fallback (sets whose doubled rows would not fit a binding: read back,
/// `plan_densify`, upload, moments regathered) against the GPU path from the same start: the
/// same rule on the same statistics, so the same counts up to the float atomics' summation
/// order, and a run that fits as well.
#[test]
fn the_cpu_densification_fallback_trains_like_the_gpu_path() {
    let Some(ctx) = gpu() else { return };
    let mut rng = SplitMix64::new(8);
    let s = scene(ctx, &mut rng);
    let init = noisy_init(&s.truth, 2, &mut rng);
    let config = eager(160, [20, 150, 25], 0);
    let run = |cpu: bool| {
        let mut trainer = Trainer::new(ctx, &init, &s.train, config.clone()).unwrap();
        trainer.force_cpu_densification(cpu);
        let mut counts = Vec::new();
        for it in 1..=160 {
            trainer.step().unwrap();
            if [40, 90, 160].contains(&it) {
                counts.push(trainer.gaussians().unwrap().len());
            }
        }
        let g = trainer.gaussians().unwrap();
        g.validate().unwrap();
        assert!(g.means.iter().flatten().all(|v| v.is_finite()));
        (
            counts,
            mean_psnr(&mut trainer, &s.test_cams, &s.test_images),
        )
    };
    let (gpu_counts, gpu_psnr) = run(false);
    let (cpu_counts, cpu_psnr) = run(true);
    eprintln!(
        "counts at 40, 90, 160: GPU {gpu_counts:?}, CPU {cpu_counts:?}; held-out PSNR GPU \
         {gpu_psnr:.2}, CPU {cpu_psnr:.2} dB"
    );
    assert!(cpu_counts[0] > init.len(), "the CPU path did not densify");
    // The first densification decides on statistics that differ only in summation order.
    let off = |a: usize, b: usize| (a as f64 - b as f64).abs() / b as f64;
    assert!(
        off(cpu_counts[0], gpu_counts[0]) < 0.02,
        "{cpu_counts:?} vs {gpu_counts:?}"
    );
    assert!(
        off(cpu_counts[2], gpu_counts[2]) < 0.10,
        "{cpu_counts:?} vs {gpu_counts:?}"
    );
    assert!(
        (cpu_psnr - gpu_psnr).abs() < 1.0,
        "{cpu_psnr} vs {gpu_psnr}"
    );
}

/// The run's last iteration changes nothing about the set: children, added points or reset
/// opacities made there would be saved untrained (sharp-dev lost 1.5 dB to 620 such children
/// at 7000 iterations). The same iteration inside a longer run does densify and reset.
#[test]
fn the_last_iteration_neither_densifies_nor_resets_opacities() {
    let Some(ctx) = gpu() else { return };
    let mut rng = SplitMix64::new(8);
    let s = scene(ctx, &mut rng);
    let init = noisy_init(&s.truth, 2, &mut rng);
    let run = |iterations: u32| {
        let config = eager(iterations, [10, 200, 20], 40);
        let mut trainer = Trainer::new(ctx, &init, &s.train, config).unwrap();
        for _ in 1..40 {
            trainer.step().unwrap();
        }
        let before = trainer.gaussians().unwrap().len();
        assert_eq!(trainer.restructures_at(40), iterations > 40);
        trainer.step().unwrap();
        let after = trainer.gaussians().unwrap();
        let top = after.opacity_logits.iter().fold(f32::MIN, |m, &o| m.max(o));
        (before, after.len(), top)
    };
    let (before, after, top) = run(40);
    assert_eq!(after, before, "the last iteration densified");
    // INRIA's reset puts every opacity at or under sigmoid⁻¹(0.01) ≈ −4.6.
    assert!(
        top > -4.0,
        "the last iteration reset opacities (largest logit {top})"
    );
    let (before, after, top) = run(60);
    assert_ne!(after, before, "iteration 40 of 60 should densify");
    assert!(
        top <= -4.5,
        "iteration 40 of 60 should reset opacities (largest logit {top})"
    );
}

/// A set at the run's cap (the adapter's binding, lowered here) stops growing: densification
/// still prunes but neither clones nor splits, and the trainer says where it stopped.
#[test]
fn density_control_stops_growing_at_the_cap() {
    let Some(ctx) = gpu() else { return };
    let mut rng = SplitMix64::new(8);
    let s = scene(ctx, &mut rng);
    let init = noisy_init(&s.truth, 2, &mut rng);
    let config = eager(120, [10, 110, 20], 0);
    let run = |cap: Option<u32>| {
        let mut trainer = Trainer::new(ctx, &init, &s.train, config.clone()).unwrap();
        if let Some(c) = cap {
            trainer.set_gaussian_cap(c);
        }
        let mut most = 0;
        for _ in 0..120 {
            trainer.step().unwrap();
            most = most.max(trainer.gaussians().unwrap().len());
        }
        (most, trainer.growth_capped_at())
    };
    let (free, none) = run(None);
    assert!(none.is_none());
    let cap = (init.len() + (free - init.len()) / 3) as u32;
    eprintln!("uncapped peak {free}, cap {cap}");
    assert!(
        free > cap as usize,
        "the uncapped run must grow past the cap"
    );
    let (capped, at) = run(Some(cap));
    assert_eq!(at, Some(cap));
    assert!(
        capped <= cap as usize,
        "{capped} Gaussians past the cap {cap}"
    );
}
