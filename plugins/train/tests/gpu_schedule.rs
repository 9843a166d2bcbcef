//! Long training on a forward-facing capture, shortened: the held-out PSNR must not fall
//! across any schedule event (SH growth, first densification, opacity reset, the first
//! prune after it, the end of densification). INRIA's preset, run on the same scene, must
//! collapse: that proves the scene sees the failure the default preset avoids.

mod common;

use cocog_engine::{Camera, GaussianParams};
use cocog_train::{DensifyConfig, SplitMix64, TrainConfig, TrainError, TrainView, Trainer};
use common::*;

/// A camera at `eye` looking along +z (OpenCV axes), the pose of a forward-facing capture.
fn forward_camera(eye: [f64; 3]) -> Camera {
    let mut m = [[0.0; 4]; 4];
    for (i, row) in m.iter_mut().enumerate().take(3) {
        row[i] = 1.0;
        row[3] = eye[i];
    }
    m[3][3] = 1.0;
    Camera {
        world_from_camera: m,
        ..look_at_origin([0.0, 0.0, -3.0])
    }
}

/// A wall of large Gaussians 2.6–3 m away and smaller objects 1–2 m away: the depth of field
/// of sharp-dev (0.4–2.3 m) seen by cameras that move a few centimetres.
fn forward_truth(rng: &mut SplitMix64) -> GaussianParams {
    let mut g = GaussianParams::default();
    let mut u = |lo: f64, hi: f64| (lo + (hi - lo) * rng.next_f64()) as f32;
    for k in 0..120 {
        let (mean, log_scale) = if k < 60 {
            (
                [u(-1.4, 1.4), u(-1.0, 1.0), u(2.6, 3.0)],
                [u(-1.9, -1.4), u(-1.9, -1.4), u(-3.0, -2.5)],
            )
        } else {
            (
                [u(-0.5, 0.5), u(-0.4, 0.4), u(1.0, 2.0)],
                [u(-3.4, -2.5), u(-3.4, -2.5), u(-3.4, -2.5)],
            )
        };
        g.means.push(mean);
        g.log_scales.push(log_scale);
        g.quats
            .push([u(0.5, 1.0), u(-0.3, 0.3), u(-0.3, 0.3), u(-0.3, 0.3)]);
        g.opacity_logits.push(u(2.0, 4.0));
        g.sh.extend([u(-1.5, 1.5), u(-1.5, 1.5), u(-1.5, 1.5)]);
    }
    g
}

/// Events of the shortened schedule: SH +1 at 40/80/120, densify every 50 from 50, opacity
/// resets at 150 and 300 (the large prune of `inria` starts after 150), densification ends at
/// 450, training at 600. Every 50 rather than 100 keeps the set small enough for lavapipe.
fn config(densify: DensifyConfig) -> TrainConfig {
    TrainConfig {
        iterations: 600,
        sh_degree_interval: 40,
        seed: 7,
        loss_every: 0,
        densify: Some(DensifyConfig {
            from_iter: 50,
            until_iter: 450,
            interval: 50,
            opacity_reset_interval: 150,
            ..densify
        }),
        ..TrainConfig::default()
    }
}

/// Held-out PSNR just before each event window closes: before densifying, before the first
/// reset, before the second (past the first prune after a reset), before the end of
/// densification, and at the end.
const CHECKPOINTS: [u32; 5] = [45, 145, 295, 445, 600];

/// A fall below the best earlier checkpoint by more than this fails. A third of the 3 dB
/// that the train log flags as a drop; INRIA's collapse on this scene is 15 dB (22.6 → 6.3 dB
/// on a longer variant of this schedule, lavapipe), and at each checkpoint the reset dip has
/// had 145 iterations to recover.
const MARGIN_DB: f64 = 1.0;

struct Run {
    psnr: Vec<(u32, f64)>,
    gaussians: Vec<u32>,
}

fn train(densify: DensifyConfig) -> Option<Result<Run, TrainError>> {
    let ctx = gpu()?;
    let mut rng = SplitMix64::new(11);
    let truth = forward_truth(&mut rng);
    let cams: Vec<Camera> = (0..12)
        .map(|i| {
            let (x, y) = (
                f64::from(i % 4) * 0.04 - 0.06,
                f64::from(i / 4) * 0.04 - 0.04,
            );
            forward_camera([x, y, 0.0])
        })
        .collect();
    let images = render(ctx, &truth, &cams);
    let (mut train, mut test_cams, mut test_images) = (Vec::new(), Vec::new(), Vec::new());
    for (i, (camera, image)) in cams.into_iter().zip(images).enumerate() {
        if i % 4 == 1 {
            test_cams.push(camera);
            test_images.push(image);
        } else {
            train.push(TrainView { camera, image });
        }
    }
    let init = noisy_init(&truth, 2, &mut rng);
    let mut trainer = Trainer::new(ctx, &init, &train, config(densify)).unwrap();
    let mut run = Run {
        psnr: Vec::new(),
        gaussians: Vec::new(),
    };
    for it in 1..=*CHECKPOINTS.last().unwrap() {
        if let Err(e) = trainer.step() {
            return Some(Err(e));
        }
        if CHECKPOINTS.contains(&it) {
            run.psnr
                .push((it, mean_psnr(&mut trainer, &test_cams, &test_images)));
            run.gaussians.push(trainer.num_gaussians());
        }
    }
    Some(Ok(run))
}

#[test]
fn default_preset_holds_its_quality_across_every_schedule_event() {
    let Some(run) = train(DensifyConfig::auto()) else {
        return;
    };
    let run = run.expect("the default preset trains through the schedule");
    eprintln!(
        "held-out PSNR {:.2?}, Gaussians {:?}",
        run.psnr, run.gaussians
    );
    let mut best = f64::MIN;
    for &(it, psnr) in &run.psnr {
        assert!(
            psnr >= best - MARGIN_DB,
            "held-out PSNR fell to {psnr:.2} dB at iteration {it}, best before {best:.2} dB: \
             {:.2?}",
            run.psnr
        );
        best = best.max(psnr);
    }
    // Densification ran (it grew the set) and the end result fits the held-out views.
    assert!(run.gaussians[1] > run.gaussians[0], "{:?}", run.gaussians);
    assert!(best > 24.0, "{:.2?}", run.psnr);
}

/// INRIA's rules on the same scene: after the first reset the large-Gaussian prune (relative
/// to a camera extent of 7 cm) deletes the wall, so the held-out PSNR falls, or every Gaussian
/// goes and training stops with an error.
#[test]
fn inria_preset_collapses_on_the_same_scene() {
    let Some(run) = train(DensifyConfig::default()) else {
        return;
    };
    match run {
        Err(e) => {
            let msg = e.to_string();
            eprintln!("inria: {msg}");
            assert!(msg.contains("pruned every Gaussian"), "{msg}");
        }
        Ok(run) => {
            eprintln!(
                "inria: held-out PSNR {:.2?}, Gaussians {:?}",
                run.psnr, run.gaussians
            );
            let before = run.psnr[1].1;
            let worst_after = run.psnr[2..].iter().map(|p| p.1).fold(f64::MAX, f64::min);
            assert!(
                worst_after < before - 3.0,
                "no collapse: {before:.2} dB before the first reset, {worst_after:.2} after"
            );
        }
    }
}
