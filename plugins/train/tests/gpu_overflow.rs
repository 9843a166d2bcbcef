//! Issue #11's overflow path on a real trainer: a step recorded with too little room for
//! its intersections changes nothing on the GPU, gives no reading, and its view is trained
//! again once the count comes back.

mod common;

use cocog_engine::{GaussianParams, GpuContext};
use cocog_train::{SplitMix64, TrainConfig, Trainer};
use common::*;

/// The test scene, a noisy start, and 40 iterations on a fixed set at SH 0 (loss read every
/// step).
fn setup(ctx: &GpuContext) -> (Scene, GaussianParams, TrainConfig) {
    let mut rng = SplitMix64::new(8);
    let s = scene(ctx, &mut rng);
    let init = noisy_init(&s.truth, 2, &mut rng);
    let config = TrainConfig {
        iterations: 40,
        loss_every: 1,
        max_sh_degree: 0,
        densify: None,
        seed: 9,
        ..TrainConfig::default()
    };
    (s, init, config)
}

#[test]
fn an_overflowed_step_is_skipped_on_the_gpu_and_its_view_trained_again() {
    let Some(ctx) = gpu() else { return };
    let (s, init, config) = setup(ctx);
    let mut trainer = Trainer::new(ctx, &init, &s.train, config.clone()).unwrap();
    let mut order = cocog_train::ViewOrder::new(s.train.len(), config.seed);
    for _ in 0..5 {
        assert_eq!(Some(trainer.step().unwrap().view), order.next_view());
    }
    // Drained first: counts still in flight would restore the room before the next step.
    trainer.finish().unwrap();
    let before = trainer.gaussians().unwrap();
    trainer.set_intersection_capacity(1);
    let starved = trainer.step().unwrap();
    assert_eq!(Some(starved.view), order.next_view());
    // The starved step changed nothing on the GPU.
    assert_eq!(trainer.gaussians().unwrap(), before);
    let mut views = Vec::new();
    let mut logged = Vec::new();
    for _ in 0..6 {
        let st = trainer.step().unwrap();
        views.push(st.view);
        logged.extend(st.readings.iter().map(|r| r.iteration));
    }
    logged.extend(trainer.finish().unwrap().iter().map(|r| r.iteration));
    assert!(
        trainer.intersection_capacity() > 1,
        "the room grew back from the reported count"
    );
    // No reading for the skipped iteration, and its view came back once the CPU learnt of it.
    assert!(!logged.contains(&starved.iteration), "{logged:?}");
    assert!(
        views.contains(&starved.view),
        "{views:?} lacks {}",
        starved.view
    );
    assert_ne!(trainer.gaussians().unwrap(), before);
}

/// A view that needs more intersections than a binding holds cannot train on this adapter:
/// the room stops at the binding, and the overflow that follows is an error naming both
/// counts instead of a retry that would overflow forever.
#[test]
fn a_view_past_the_intersection_binding_is_an_error() {
    let Some(ctx) = gpu() else { return };
    let (s, init, config) = setup(ctx);
    let mut trainer = Trainer::new(ctx, &init, &s.train, config).unwrap();
    trainer.step().unwrap();
    trainer.finish().unwrap();
    // Room for 16 intersections: far fewer than any view of the scene needs.
    trainer.set_render_binding_limit(64);
    assert_eq!(trainer.intersection_capacity(), 16);
    let err = (0..10)
        .map(|_| trainer.step().and_then(|_| trainer.finish().map(|_| ())))
        .find_map(Result::err)
        .expect("an error within 10 steps");
    let msg = err.to_string();
    assert!(
        msg.contains("tile intersections") && msg.contains("holds 16"),
        "{msg}"
    );
}
