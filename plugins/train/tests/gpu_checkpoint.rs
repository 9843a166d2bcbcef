//! A run interrupted by a checkpoint continues as if uninterrupted.

mod common;

use cocog_engine::coc::CocVariant;
use cocog_train::{CocTrainConfig, DensifyConfig, SplitMix64, TrainConfig, TrainState, Trainer};
use common::{gpu, noisy_init, scene};

fn config() -> TrainConfig {
    TrainConfig {
        iterations: 80,
        max_sh_degree: 1,
        // SH growth after the checkpoint, densification only before it: densification
        // amplifies the rounding differences of float atomics far beyond what a lost Adam
        // moment would cause, so the window after the resume must not densify.
        sh_degree_interval: 50,
        seed: 11,
        loss_every: 0,
        densify: Some(DensifyConfig {
            from_iter: 10,
            until_iter: 35,
            interval: 10,
            opacity_reset_interval: 30,
            ..DensifyConfig::default()
        }),
        ..TrainConfig::default()
    }
}

fn max_abs_diff(a: &[f32], b: &[f32]) -> f32 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f32::max)
}

#[test]
fn resuming_from_a_saved_checkpoint_matches_the_uninterrupted_run() {
    let Some(ctx) = gpu() else { return };
    let mut rng = SplitMix64::new(21);
    let s = scene(ctx, &mut rng);
    let init = noisy_init(&s.truth, 2, &mut rng);

    let mut straight = Trainer::new(ctx, &init, &s.train, config()).unwrap();
    let mut views = (Vec::new(), Vec::new());
    for _ in 0..40 {
        views.0.push(straight.step().unwrap().view);
    }
    assert!(straight.num_gaussians() > init.len() as u32, "densified");
    let dir = tempfile::tempdir().unwrap();
    let saved = straight.snapshot(1).unwrap();
    saved.save(dir.path()).unwrap();

    let loaded = TrainState::load(dir.path()).unwrap();
    assert_eq!(loaded, saved);
    let mut resumed = Trainer::resume(ctx, &loaded, &s.train, config()).unwrap();
    // The GPU round trip is exact.
    assert_eq!(resumed.snapshot(1).unwrap(), saved);
    assert_eq!(resumed.iteration(), 40);

    let mut stats = (Vec::new(), Vec::new());
    for _ in 40..80 {
        let a = straight.step().unwrap();
        let b = resumed.step().unwrap();
        views.0.push(a.view);
        views.1.push(b.view);
        stats.0.push((a.iteration, a.sh_degree, a.num_gaussians));
        stats.1.push((b.iteration, b.sh_degree, b.num_gaussians));
    }
    // Same views in the same order, same SH growth and densification outcome.
    assert_eq!(&views.0[40..], &views.1[..]);
    assert_eq!(stats.0, stats.1);
    let (a, b) = (straight.gaussians().unwrap(), resumed.gaussians().unwrap());
    // Float atomics sum gradients in a varying order, so the runs agree to rounding only
    // (~1e-7 here); restarting Adam's moments instead moves the means by ~1e-2.
    let d = max_abs_diff(a.means.as_flattened(), b.means.as_flattened());
    let o = max_abs_diff(&a.opacity_logits, &b.opacity_logits);
    let sh = max_abs_diff(&a.sh, &b.sh);
    eprintln!(
        "{} Gaussians; max |Δ| means {d:e}, opacity logits {o:e}, SH {sh:e}",
        a.len()
    );
    assert!(
        d < 1e-4 && o < 1e-3 && sh < 1e-3,
        "means {d}, opacity {o}, SH {sh}"
    );
}

/// CoCoGaussian's lens model (h_θ, F, the focus distances and their Adam moments) survives a
/// checkpoint: the resumed run continues the blurred phase as the uninterrupted one does.
#[test]
fn a_cocog_run_resumes_with_its_lens_model() {
    if gpu().is_none() {
        return;
    }
    // F's maps in f32. In f16 a sum reordered by the float atomics can flip a stored value's
    // rounding by an ulp (5e-4 relative), which ten Adam steps carry into F's weights as
    // differences of 6e-6 to 1.8e-5 between two runs (against 1.5e-8 in f32; measured on
    // lavapipe), the scale of what this test must catch.
    let mut own =
        cocog_engine::GpuContext::new().expect("the shared context's adapter opens again");
    own.shader_f16 = false;
    let ctx = &own;
    let mut rng = SplitMix64::new(22);
    let s = scene(ctx, &mut rng);
    let init = noisy_init(&s.truth, 2, &mut rng);
    let config = || TrainConfig {
        coc: Some(CocTrainConfig {
            blur_start: 6,
            composite_start: 12,
            compositor_channels: 4,
            ..CocTrainConfig::new(CocVariant::Code)
        }),
        densify: None,
        ..config()
    };
    let mut straight = Trainer::new(ctx, &init, &s.train, config()).unwrap();
    for _ in 0..20 {
        straight.step().unwrap();
    }
    let dir = tempfile::tempdir().unwrap();
    let saved = straight.snapshot(1).unwrap();
    let lens = saved
        .coc
        .as_ref()
        .expect("a cocog run saves its lens model");
    assert!(lens.focus.is_some(), "the blurred phase has started");
    assert!(
        lens.compositor_moments.v.iter().any(|v| *v > 0.0),
        "F has trained"
    );
    saved.save(dir.path()).unwrap();
    let loaded = TrainState::load(dir.path()).unwrap();
    assert_eq!(loaded, saved);
    let mut resumed = Trainer::resume(ctx, &loaded, &s.train, config()).unwrap();
    assert_eq!(resumed.snapshot(1).unwrap(), saved);
    for _ in 20..30 {
        let (a, b) = (straight.step().unwrap(), resumed.step().unwrap());
        assert_eq!((a.iteration, a.view), (b.iteration, b.view));
    }
    let (a, b) = (straight.snapshot(1).unwrap(), resumed.snapshot(1).unwrap());
    let (ka, kb) = (a.coc.unwrap(), b.coc.unwrap());
    let fa = ka.focus.unwrap().values;
    let fb = kb.focus.unwrap().values;
    let d_means = max_abs_diff(a.params.means.as_flattened(), b.params.means.as_flattened());
    let d_mlp = max_abs_diff(&ka.mlp, &kb.mlp);
    // F's parameters whose gradient is within 10³ of the largest: Adam (ε = 1e-15, as the released
    // code) turns the noise of near-zero gradients (a conv bias before ReLU + InstanceNorm:
    // v ≈ 1e-21) into steps of up to the learning rate, which differ between any two runs.
    let v_top = ka.compositor_moments.v.iter().copied().fold(0.0, f32::max);
    let d_f = ka
        .compositor
        .iter()
        .zip(&kb.compositor)
        .zip(&ka.compositor_moments.v)
        .filter(|(_, v)| **v > 1e-6 * v_top)
        .map(|((x, y), _)| (x - y).abs())
        .fold(0.0, f32::max);
    let d_focus = max_abs_diff(&fa, &fb);
    eprintln!("max |Δ| means {d_means:e}, h_θ {d_mlp:e}, F {d_f:e}, focus {d_focus:e}");
    // Float atomics reorder sums (rounding); restarting the lens model's Adam moments instead
    // moves h_θ's weights by ~1e-3 in ten steps (the kernel learning rate).
    assert!(
        d_means < 1e-4 && d_mlp < 1e-5 && d_f < 1e-5 && d_focus < 1e-6,
        "means {d_means}, h_θ {d_mlp}, F {d_f}, focus {d_focus}"
    );
    // Asking for another lens layout is refused, naming both.
    let mut other = config();
    if let Some(c) = other.coc.as_mut() {
        c.compositor_channels = 8;
    }
    let err = Trainer::resume(ctx, &loaded, &s.train, other)
        .err()
        .expect("a different compositor width must be refused")
        .to_string();
    assert!(
        err.contains("4 compositor channels") && err.contains("8 compositor channels"),
        "{err}"
    );
}
