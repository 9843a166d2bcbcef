//! The execution model of issue #11, counted on the engine's own counters: once warm, a
//! training step creates no GPU buffer, creates no bind group, waits on no read-back of its
//! own work, and is one submission. Its own binary: the counters are per context, and tests
//! in one binary share the context.

mod common;

use cocog_engine::CounterSnapshot;
use cocog_train::{DensifyConfig, SplitMix64, TrainConfig, Trainer};
use common::*;

/// Per-iteration counter differences of `iterations` steps.
fn count_steps(trainer: &mut Trainer<'_>, iterations: u32) -> Vec<(u32, CounterSnapshot)> {
    let ctx = gpu().expect("checked by the caller");
    (0..iterations)
        .map(|_| {
            let before = ctx.counters.snapshot();
            let stats = trainer.step().unwrap();
            (stats.iteration, ctx.counters.snapshot() - before)
        })
        .collect()
}

/// The three runs' settings: `iterations` steps from seed 4 at SH 0, loss read every 10.
fn config(iterations: u32, densify: Option<DensifyConfig>) -> TrainConfig {
    TrainConfig {
        iterations,
        loss_every: 10,
        max_sh_degree: 0,
        densify,
        seed: 4,
        ..TrainConfig::default()
    }
}

/// (buffers created, blocking reads, submissions, bind groups created) of one step.
fn ops(c: &CounterSnapshot) -> (u64, u64, u64, u64) {
    (
        c.buffers_created,
        c.blocking_reads,
        c.submissions,
        c.bind_groups_created,
    )
}

#[test]
fn warm_steps_allocate_nothing_wait_for_nothing_and_submit_once() {
    let Some(ctx) = gpu() else { return };
    let mut rng = SplitMix64::new(21);
    let s = scene(ctx, &mut rng);
    let init = noisy_init(&s.truth, 2, &mut rng);

    // Without density control, every step after a short warm-up (the workspace and the
    // read-back slots growing to size, including a logging step's) must be clean.
    let mut trainer = Trainer::new(ctx, &init, &s.train, config(120, None)).unwrap();
    let counts = count_steps(&mut trainer, 120);
    for &(it, c) in counts.iter().filter(|(it, _)| *it > 40) {
        assert_eq!(ops(&c), (0, 0, 1, 0), "iteration {it}: {c}");
        assert!(c.dispatches > 20, "iteration {it}: {c}");
    }
    let readings = trainer.finish().unwrap();
    assert!(
        readings
            .iter()
            .all(|r| r.psnr.is_finite() && r.loss.is_finite())
    );

    // Densification and opacity resets run inside the step: once the buffers have room for
    // twice the count, a densifying or resetting step is as clean as any. No Gaussian is hot
    // here, so the count never grows past that room; the full pipeline still runs (scans, candidates, the prune, every gather).
    let densify = TrainConfig::default().densify.unwrap();
    let cold = DensifyConfig {
        from_iter: 50,
        until_iter: 400,
        interval: 50,
        opacity_reset_interval: 100,
        grad_threshold: f32::MAX,
        ..densify
    };
    let mut trainer = Trainer::new(ctx, &init, &s.train, config(400, Some(cold))).unwrap();
    let counts = count_steps(&mut trainer, 400);
    // The first densification (100) grows the buffers, the steps after it the workspace, which
    // empties the bind-group cache, so the next densification (150) and reset (200) bind anew.
    // At 400 statistics stop, which moves the uniforms of the Adam dispatches behind them: they
    // bind anew once.
    for &(it, c) in &counts {
        if (211..400).contains(&it) {
            assert_eq!(ops(&c), (0, 0, 1, 0), "iteration {it}: {c}");
        }
        if it % 50 == 0 {
            eprintln!("density control at {it}: {c}");
        }
    }

    // With growth, the steps between events are clean again once the workspace has grown to
    // the new count.
    let growing = DensifyConfig {
        from_iter: 50,
        until_iter: 150,
        interval: 50,
        opacity_reset_interval: 100,
        ..densify
    };
    let mut trainer = Trainer::new(ctx, &init, &s.train, config(200, Some(growing))).unwrap();
    let counts = count_steps(&mut trainer, 200);
    for &(it, c) in &counts {
        if [50, 100, 150].contains(&it) {
            eprintln!("densification iteration {it}: {c}");
        }
    }
    // Densification (50, 100) changes the count; 20 steps later everything has settled.
    for &(it, c) in counts.iter().filter(|(it, _)| (170..=200).contains(it)) {
        let (buffers, reads, submissions, _) = ops(&c);
        assert_eq!(
            (buffers, reads, submissions),
            (0, 0, 1),
            "iteration {it}: {c}"
        );
    }
}
