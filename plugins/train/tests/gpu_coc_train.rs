//! CoCoGaussian end to end on a tiny forward-facing defocus scene: training photos rendered
//! through a thin lens (the f64 reference, aperture sampled) focused near or far, sharp
//! held-out views.
//!
//! What holds and is asserted: a CoC step with h_θ's heads at zero is exactly a 3DGS step (the
//! wiring); each training photo rendered through its own learned lens (`render
//! --as-photographed`) matches it better than the sharp render of the same Gaussians (measured
//! 26.8 vs 24.3 dB, asserted ≥ 1 dB) and better than plain 3DGS fits it (26.8 vs 26.1 dB over
//! runs that vary by ±0.1 dB: GPU sums in another order each run; asserted ≥ 0.25 dB).
//! What does not hold, and is only printed: on this 100-Gaussian scene after 500 iterations the
//! base Gaussians alone score below plain 3DGS on the sharp held-out views (24.2 vs 25.8 dB),
//! and the learned focus distances stay near their mean-depth start (≈ 2.9 against 1.6 / 3.6).

mod common;

use cocog_engine::coc::{CocConfig, CocVariant, Frame, Lens, Refocus};
use cocog_engine::nn::CompositeMode;
use cocog_engine::reference::Gaussians64;
use cocog_engine::{Camera, GaussianParams};
use cocog_metrics::psnr;
use cocog_synth::lens::{BlurSpace, ThinLens, render_thin_lens};
use cocog_train::{
    CocTrainConfig, DROP_DB, DensifyConfig, SplitMix64, TrainConfig, TrainView, Trainer,
};
use common::*;

const NEAR: f64 = 1.6;
const FAR: f64 = 3.6;
/// CoC up to 2·0.12·53·(1/1.6 − 1/3.6) ≈ 4.4 px at 48×36: most of the image is visibly blurred
/// in every photo, one depth layer at a time.
const APERTURE: f64 = 0.12;
const ITERATIONS: u32 = 500;

/// A camera at `eye` looking down +z (forward-facing rig).
fn forward(eye: [f64; 3]) -> Camera {
    let mut m = [[0.0; 4]; 4];
    for i in 0..3 {
        m[i][i] = 1.0;
        m[i][3] = eye[i];
    }
    m[3][3] = 1.0;
    Camera {
        fx: 1.1 * f64::from(W),
        fy: 1.1 * f64::from(W),
        cx: 0.5 * f64::from(W),
        cy: 0.5 * f64::from(H),
        width: W,
        height: H,
        world_from_camera: m,
    }
}

/// Two textured layers of opaque Gaussians, one at each focus depth.
fn layers(rng: &mut SplitMix64) -> GaussianParams {
    let mut g = GaussianParams::default();
    let mut u = |lo: f64, hi: f64| (lo + (hi - lo) * rng.next_f64()) as f32;
    for (z, half, n) in [(NEAR, 0.45, 40), (FAR, 1.0, 60)] {
        for _ in 0..n {
            let (x, y) = (u(-half, half), u(-0.75 * half, 0.75 * half));
            g.means.push([x, y, z as f32 + u(-0.05, 0.05)]);
            let s = if z < 2.0 { -3.3 } else { -2.6 };
            g.log_scales
                .push([u(s, s + 0.4), u(s, s + 0.4), u(-4.0, -3.5)]);
            g.quats
                .push([1.0, u(-0.2, 0.2), u(-0.2, 0.2), u(-0.2, 0.2)]);
            g.opacity_logits.push(u(2.0, 4.0));
            g.sh.extend([u(-1.5, 1.5), u(-1.5, 1.5), u(-1.5, 1.5)]);
        }
    }
    g
}

struct Defocus {
    truth: GaussianParams,
    train: Vec<TrainView>,
    /// Per training view: its true focus distance.
    focus: Vec<f64>,
    test_cams: Vec<Camera>,
    test_images: Vec<Vec<[f32; 3]>>,
}

fn defocus_scene(rng: &mut SplitMix64) -> Defocus {
    let truth = layers(rng);
    let g64 = Gaussians64::from(&truth);
    let mut train = Vec::new();
    let mut focus = Vec::new();
    for i in 0..8 {
        let eye = [
            0.04 * f64::from(i % 4) - 0.06,
            0.03 * f64::from(i / 4) - 0.015,
            0.0,
        ];
        let cam = forward(eye);
        let d = if i % 2 == 0 { NEAR } else { FAR };
        let lens = ThinLens {
            focus_distance: d,
            aperture_radius: APERTURE / 2.0,
        };
        let img = render_thin_lens(&g64, &cam, Some(lens), 48, [0.0; 3], BlurSpace::Display);
        train.push(TrainView {
            camera: cam,
            image: img.iter().map(|p| p.map(|v| v as f32)).collect(),
        });
        focus.push(d);
    }
    let test_cams = vec![forward([0.01, 0.005, 0.0]), forward([-0.03, 0.02, 0.0])];
    let test_images = test_cams
        .iter()
        .map(|c| {
            render_thin_lens(&g64, c, None, 0, [0.0; 3], BlurSpace::Display)
                .iter()
                .map(|p| p.map(|v| v as f32))
                .collect()
        })
        .collect();
    Defocus {
        truth,
        train,
        focus,
        test_cams,
        test_images,
    }
}

/// What a run left: held-out PSNR of the base Gaussians, the fit to the blurred photos, the
/// learned focus distances, and the scene with its lens model (cocog only).
struct Trained {
    psnr: f64,
    fit: f64,
    /// Mean PSNR of the (sharp) render of every training view against its blurred photo.
    train_psnr: f64,
    focus: Vec<f64>,
    gaussians: GaussianParams,
    lens: Option<cocog_formats::lens_model::LensModel>,
}

fn train(scene: &Defocus, init: &GaussianParams, coc: Option<CocTrainConfig>) -> Trained {
    let ctx = gpu().expect("checked by the caller");
    let config = TrainConfig {
        iterations: ITERATIONS,
        max_sh_degree: 0,
        seed: 3,
        loss_every: 50,
        densify: None,
        coc,
        ..TrainConfig::default()
    };
    let mut trainer = Trainer::new(ctx, init, &scene.train, config).unwrap();
    let mut r = Vec::new();
    for _ in 0..ITERATIONS {
        r.extend(trainer.step().unwrap().readings);
    }
    r.extend(trainer.finish().unwrap());
    // The loss of the last few logged iterations: how well the rendering model explains the
    // blurred photos (for CoCoGaussian, the composite of the CoC sets).
    let tail: Vec<f64> = r.iter().rev().take(4).map(|x| x.loss).collect();
    let fit = tail.iter().sum::<f64>() / tail.len().max(1) as f64;
    let psnr = mean_psnr(&mut trainer, &scene.test_cams, &scene.test_images);
    let (cams, photos): (Vec<Camera>, Vec<Vec<[f32; 3]>>) = scene
        .train
        .iter()
        .map(|v| (v.camera, v.image.clone()))
        .unzip();
    let train_psnr = mean_psnr(&mut trainer, &cams, &photos);
    Trained {
        psnr,
        fit,
        train_psnr,
        focus: trainer.focus_distances().unwrap(),
        gaussians: trainer.gaussians().unwrap(),
        lens: trainer.lens_model().unwrap(),
    }
}

/// Mean PSNR against the training photos of each photo rendered through its own learned lens
/// (as `cocog render --as-photographed` does) and of the sharp render of the same Gaussians.
fn photographed_and_sharp(scene: &Defocus, run: &Trained) -> (f64, f64) {
    let ctx = gpu().expect("checked by the caller");
    let model = run.lens.as_ref().expect("a cocog run has a lens model");
    let config = CocConfig {
        variant: CocVariant::parse(&model.variant).unwrap(),
        copies: model.copies,
        width: model.width,
        centred: model.centred,
        modulate_base: model.modulate_base,
    };
    let frame = Frame {
        origin: model.origin,
        scale: model.scale,
    };
    let mut refocus = Refocus::new(
        ctx,
        config,
        model.compositor_channels,
        frame,
        &run.gaussians,
        &model.mlp,
        &model.compositor,
    )
    .unwrap();
    let (mut photographed, mut sharp) = (0.0, 0.0);
    for (k, view) in scene.train.iter().enumerate() {
        let lens = Lens {
            focus_distance: model.focus_distances[k],
            aperture: 1.0,
            learned_aperture: model.apertures.get(k).copied().unwrap_or(0.0),
            composite: CompositeMode::Learned,
        };
        let target = to_float(&view.image);
        let img = refocus.render(&view.camera, [0.0; 3], &lens).unwrap();
        photographed += psnr(&to_float(&img.color), &target);
        let img = refocus.render_sharp(&view.camera, [0.0; 3]).unwrap();
        sharp += psnr(&to_float(&img.color), &target);
    }
    let n = scene.train.len() as f64;
    (photographed / n, sharp / n)
}

#[test]
fn cocog_fits_the_blurred_photos_that_3dgs_cannot() {
    if gpu().is_none() {
        return;
    }
    let mut rng = SplitMix64::new(21);
    let scene = defocus_scene(&mut rng);
    let init = noisy_init(&scene.truth, 1, &mut rng);
    let mut coc = CocTrainConfig::new(CocVariant::Code);
    coc.blur_start = 100;
    coc.composite_start = 250;
    coc.compositor_channels = 8;
    let plain = train(&scene, &init, None);
    assert!(plain.focus.is_empty(), "3dgs learns no focus distances");
    assert!(plain.lens.is_none(), "3dgs writes no lens model");
    let cocog = train(&scene, &init, Some(coc));
    let (plain_fit, cocog_fit, focus) = (plain.fit, cocog.fit, &cocog.focus);
    // Measured, not asserted (see the module comment): held-out sharpness and focus recovery.
    eprintln!(
        "held-out PSNR: 3dgs {:.2} dB, cocog {:.2} dB",
        plain.psnr, cocog.psnr
    );
    eprintln!("training loss: 3dgs {plain_fit:.4}, cocog {cocog_fit:.4}");
    eprintln!("focus: learned {focus:.3?}, true {:.3?}", scene.focus);
    assert_eq!(focus.len(), scene.train.len());
    assert!(focus.iter().all(|d| d.is_finite() && *d > 0.0));
    assert!(cocog.psnr.is_finite());
    // The training photos rendered through their own learned lenses (`render
    // --as-photographed`) match the photos better than the sharp base render does.
    let (photographed, sharp) = photographed_and_sharp(&scene, &cocog);
    eprintln!(
        "training photos: cocog as photographed {photographed:.2} dB, its sharp render \
         {sharp:.2} dB; 3dgs {:.2} dB",
        plain.train_psnr
    );
    assert!(
        photographed > sharp + 1.0,
        "rendering each photo through its learned lens gains too little: {photographed:.2} dB \
         vs sharp {sharp:.2} dB"
    );
    // Sharp Gaussians cannot reproduce defocused photos; the CoC sets, composited through
    // each photo's learned lens, can. Both are scored over every training photo at the end
    // (the training loss tail is one view per reading, too noisy for a margin).
    assert!(
        photographed > plain.train_psnr + 0.25,
        "cocog's composite fits the blurred photos no better: {photographed:.2} dB vs 3dgs \
         {:.2} dB",
        plain.train_psnr
    );
}

/// `iterations` steps on a fixed Gaussian set (no densification, SH 0), a reading every step.
fn fixed_set_run(iterations: u32, coc: Option<CocTrainConfig>) -> TrainConfig {
    TrainConfig {
        iterations,
        max_sh_degree: 0,
        seed: 3,
        loss_every: 1,
        densify: None,
        coc,
        ..TrainConfig::default()
    }
}

/// The paper variant through its CoC sets from the first step, with h_θ, F and the focus
/// distances frozen at their start.
fn frozen_paper() -> CocTrainConfig {
    let mut coc = CocTrainConfig::new(CocVariant::Paper);
    coc.blur_start = 1;
    coc.kernel_lr_init = 1e-30;
    coc.kernel_lr_final = 1e-30;
    coc
}

/// The paper variant's aperture K starts narrow: from the true scene, with h_θ at its default
/// init and frozen, the first steps through the M + 1 sets fit the blurred photos within
/// `10 dB` of the sharp Gaussians instead of scattering the copies. Measured: 33.68 dB against
/// 40.78 with the narrow start; 15.59 with the untrained head's K ≈ 0.69, the start that
/// collapsed both dev scenes at the blur start.
#[test]
fn the_paper_aperture_starts_narrow() {
    if gpu().is_none() {
        return;
    }
    let ctx = gpu().unwrap();
    let mut rng = SplitMix64::new(8);
    let scene = defocus_scene(&mut rng);
    let config = |coc| fixed_set_run(8, coc);
    let coc = frozen_paper();
    let fit = |coc: Option<CocTrainConfig>| {
        let mut t = Trainer::new(ctx, &scene.truth, &scene.train, config(coc)).unwrap();
        let mut r = Vec::new();
        for _ in 0..8 {
            r.extend(t.step().unwrap().readings);
        }
        r.extend(t.finish().unwrap());
        r.iter().map(|r| r.psnr).sum::<f64>() / r.len() as f64
    };
    let (plain, paper) = (fit(None), fit(Some(coc)));
    eprintln!("training PSNR over the first 8 steps: plain {plain:.2} dB, paper {paper:.2} dB");
    assert!(
        paper > plain - 10.0,
        "the paper variant's first steps fit at {paper:.2} dB against the sharp Gaussians' \
         {plain:.2} dB: its circle of confusion starts too wide"
    );
}

/// With h_θ's heads at zero (and frozen) every set is the base itself, so an averaged CoC step
/// is a plain step with the gradient summed over M + 1 identical renders weighted 1/(M + 1):
/// the same update. Three steps, so Adam's later updates compare gradient magnitudes, not just
/// signs. Checks the set layout, the opacity/SH repetition, the adjoint's sums and the
/// rotation's normalisation against the plain path, on blurred photos.
#[test]
fn a_cocog_step_with_zero_heads_is_a_3dgs_step() {
    if gpu().is_none() {
        return;
    }
    let ctx = gpu().unwrap();
    let mut rng = SplitMix64::new(8);
    let scene = defocus_scene(&mut rng);
    // The truth's anisotropic shapes with wrong colours and opacities: an isotropic start
    // (INRIA's) gives rotations no effect, so their gradients are rounding noise that Adam
    // amplifies into ±lr steps on either path.
    let mut init = scene.truth.clone();
    for v in init.sh.iter_mut().chain(&mut init.opacity_logits) {
        *v = (rng.next_f64() * 2.0 - 1.0) as f32;
    }
    let config = |coc| fixed_set_run(3, coc);
    let mut coc = frozen_paper();
    coc.composite_start = 100;
    // Frozen h_θ with zero heads: every step's sets are exact copies of the base.
    coc.head_init_scale = 0.0;
    let mut plain = Trainer::new(ctx, &init, &scene.train, config(None)).unwrap();
    let mut cocog = Trainer::new(ctx, &init, &scene.train, config(Some(coc))).unwrap();
    for _ in 0..3 {
        plain.step().unwrap();
        cocog.step().unwrap();
    }
    let (a, b) = (plain.gaussians().unwrap(), cocog.gaussians().unwrap());
    let gap = |x: &[f32], y: &[f32]| {
        x.iter()
            .zip(y)
            .map(|(p, q)| (p - q).abs())
            .fold(0.0f32, f32::max)
    };
    let unit = |q: &[[f32; 4]]| -> Vec<f32> {
        q.iter()
            .flat_map(|v| {
                let n = v.iter().map(|x| x * x).sum::<f32>().sqrt();
                v.map(|x| x / n)
            })
            .collect()
    };
    let mut bad = Vec::new();
    for (what, start, x, y) in [
        (
            "means",
            init.means.as_flattened(),
            a.means.as_flattened(),
            b.means.as_flattened(),
        ),
        (
            "log-scales",
            init.log_scales.as_flattened(),
            a.log_scales.as_flattened(),
            b.log_scales.as_flattened(),
        ),
        // INRIA starts every rotation at (1, 0, 0, 0), where w is the radial direction: its
        // gradient is zero but for rounding, and Adam turns that into a ±lr step of either sign
        // that changes only |q|. The rotations themselves are compared.
        (
            "rotations",
            &unit(&init.quats),
            &unit(&a.quats),
            &unit(&b.quats),
        ),
        (
            "opacities",
            &init.opacity_logits[..],
            &a.opacity_logits[..],
            &b.opacity_logits[..],
        ),
        ("SH", &init.sh[..], &a.sh[..], &b.sh[..]),
    ] {
        // Each group against how far the plain steps moved it (its learning rate's scale).
        let moved = gap(start, x);
        let d = gap(x, y);
        eprintln!("{what}: moved {moved:e}, paths differ by {d:e}");
        if moved == 0.0 || d > 0.01 * moved {
            bad.push(format!(
                "{what} differ by {d:e} after 3 steps (moved {moved:e})"
            ));
        }
    }
    assert!(bad.is_empty(), "{bad:?}");
}

/// Held-out PSNR of the base Gaussians at the checkpoints of a shortened CoCoGaussian
/// schedule crossing every event, the Gaussian count there, and the learned focus distances
/// at the end. `refocus_every` > 0 starts the focus by depth from defocus and estimates it
/// again at that interval to the end.
fn schedule_run(
    scene: &Defocus,
    init: &GaussianParams,
    add_points_at: u32,
    refocus_every: u32,
) -> (Vec<(u32, f64, u32)>, Vec<f64>) {
    let ctx = gpu().expect("checked by the caller");
    let mut coc = CocTrainConfig::new(CocVariant::Lens);
    coc.blur_start = BLUR_START;
    coc.composite_start = COMPOSITE_START;
    coc.compositor_channels = 8;
    coc.estimate_focus = refocus_every > 0;
    (coc.refocus_every, coc.refocus_until) = (refocus_every, 600);
    let config = TrainConfig {
        iterations: 600,
        sh_degree_interval: 40,
        seed: 5,
        loss_every: 0,
        densify: Some(DensifyConfig {
            from_iter: 50,
            until_iter: 450,
            interval: 50,
            add_points_at,
            add_points_count: 150,
            // Four times INRIA's threshold keeps the set at lavapipe size on 48×36 photos
            // (eight times was worse: 17.0 dB at the end, two runs).
            grad_threshold: 8e-4,
            ..DensifyConfig::deblur()
        }),
        coc: Some(coc),
        ..TrainConfig::default()
    };
    let mut trainer = Trainer::new(ctx, init, &scene.train, config).unwrap();
    let mut out = Vec::new();
    for it in 1..=600 {
        trainer.step().unwrap();
        if SCHEDULE_CHECKPOINTS.contains(&it) {
            let psnr = mean_psnr(&mut trainer, &scene.test_cams, &scene.test_images);
            out.push((it, psnr, trainer.num_gaussians()));
        }
    }
    (out, trainer.focus_distances().unwrap())
}

const BLUR_START: u32 = 100;
/// A hundred iterations after the point addition: its re-initialisation restarts Adam (the
/// released code rebuilds its optimizer), whose first steps are its learning rates, so the
/// held-out PSNR dips there (14.1 dB at 170, 20.4 at 195) and is back above its earlier best
/// by 245 (24.9); a checkpoint 45 iterations after it measured that dip, not a collapse.
const COMPOSITE_START: u32 = 250;
const ADD_POINTS_AT: u32 = 150;
/// Before the CoC sets start, before the point addition, before F starts, before the end of
/// densification (past SH growth at 40/80/120 and densification every 50), and at the end.
const SCHEDULE_CHECKPOINTS: [u32; 5] = [95, 145, 245, 445, 600];

/// CoCoGaussian's shortened schedule (deblur preset: no opacity reset, depth-weighted
/// pruning; the default lens variant) crossing SH growth, densification, the blur start, the
/// point addition, the compositor start and the end of densification: the sharp held-out PSNR
/// must not collapse (fall more than `DROP_DB`, the train log's collapse mark) below its best
/// earlier checkpoint, and must end `GAIN_DB` above the warm-up's (the CoC sets must sharpen
/// the base, not merely not ruin it).
/// Measured on lavapipe (GPU sums in another order each run): 22.0 dB (95, warm-up) → 23.8
/// (145, after the blur start) → 24.6 (245, after the point addition) → 29.1 (445, end of
/// densification) → 30.3 (600), no fall anywhere (session 40, with Adam restarted at the
/// addition; before, four runs read 23.3–23.9 at 195 and 28.0–29.9 at 600). The
/// code variant on the same schedule fell 0.6–3.3 dB under densification and ended at
/// 18.9–21.3 dB, below its warm-up, which the gain check refuses. Plain 3DGS on the same
/// schedule ends at 35.0–36.9 dB (two runs): here the lens does not find the focus (every
/// view's, near- and far-focused alike, ends at 2.7–2.9 between the layers at 1.6 and 3.6;
/// 2.2–2.5 from the depth-from-defocus start or with 10× the kernel learning rate), so this
/// checks the schedule, not the gain over 3DGS (issue 12).
#[test]
fn cocog_holds_its_quality_across_every_schedule_event() {
    if gpu().is_none() {
        return;
    }
    let mut rng = SplitMix64::new(21);
    let scene = defocus_scene(&mut rng);
    let init = noisy_init(&scene.truth, 1, &mut rng);
    let (run, _) = schedule_run(&scene, &init, ADD_POINTS_AT, 0);
    eprintln!("held-out PSNR and Gaussians at checkpoints: {run:.2?}");
    let (before, after) = (run[1].2, run[2].2);
    assert!(after > before, "the point addition added nothing: {run:?}");
    let mut best = f64::MIN;
    for &(it, psnr, _) in &run {
        assert!(
            psnr >= best - DROP_DB,
            "held-out PSNR fell to {psnr:.2} dB at iteration {it}, best before {best:.2} dB: \
             {run:.2?}"
        );
        best = best.max(psnr);
    }
    let (warm, end) = (run[0].1, run[run.len() - 1].1);
    assert!(
        end >= warm + GAIN_DB,
        "held-out PSNR ended at {end:.2} dB, less than {GAIN_DB} dB above the warm-up's \
         {warm:.2} dB: {run:.2?}"
    );
}

/// Below the smallest measured gain (+6.0 dB over four runs), with room for GPU summation order.
const GAIN_DB: f64 = 4.0;

/// The same scene and schedule with the focus estimated by depth from defocus at the blur
/// start and again every 50 iterations (`--refocus-every 50`): the photos alternate between
/// focus on the layer at 1.6 and on the one at 3.6 over a 6 cm baseline, where the gradient
/// alone leaves every photo's focus at 2.7–2.9 (the test above). Refocused, every
/// near-focused photo should end nearer than every far-focused one, and the base above what
/// the gradient-only run ever reached (28.0–29.9 dB over five runs).
/// Not in CI: it holds in 2 of 4 runs on lavapipe. Found both planes: 37.09 dB (focus
/// 1.61–1.63 / 2.78–3.34) and 35.81 dB (1.62–1.68 / 3.41–3.45); locked every photo onto the
/// near plane: 30.58 dB (1.63–1.74 for all eight), and one more failure whose figures were
/// lost. Plain 3DGS: 35.0–36.9 dB; the true focus as the start: 37.71 dB. That is why
/// refocusing is off by default (BENCHMARKS.md, issue 12).
#[test]
#[ignore = "bistable: 2 of 4 runs on lavapipe lock every photo onto one focus plane"]
fn refocusing_finds_the_near_and_far_focus_of_the_photos() {
    if gpu().is_none() {
        return;
    }
    let mut rng = SplitMix64::new(21);
    let scene = defocus_scene(&mut rng);
    let init = noisy_init(&scene.truth, 1, &mut rng);
    let (run, focus) = schedule_run(&scene, &init, ADD_POINTS_AT, 50);
    eprintln!("held-out PSNR and Gaussians: {run:.2?}; focus {focus:.2?}");
    let side = |want: f64| -> Vec<f64> {
        (focus.iter().zip(&scene.focus))
            .filter(|&(_, &t)| t == want)
            .map(|(&f, _)| f)
            .collect()
    };
    let (near, far) = (side(NEAR), side(FAR));
    let nearest_far = far.iter().copied().fold(f64::MAX, f64::min);
    assert!(
        near.iter().all(|&d| d < nearest_far),
        "near-focused photos at {near:.2?}, far-focused at {far:.2?}"
    );
    let end = run[run.len() - 1].1;
    assert!(
        end >= REFOCUSED_DB,
        "held-out PSNR ended at {end:.2} dB, below {REFOCUSED_DB} dB: {run:.2?}"
    );
}

/// Above the gradient-only runs' best (29.9 dB), below the runs that found both planes (35.8).
const REFOCUSED_DB: f64 = 31.0;

/// The trainer's point addition: at its iteration the set grows by the candidates near the
/// Gaussians, every Gaussian restarts round with opacity 0.1 (checked on the parameters read
/// back right after that step), and training goes on from there.
#[test]
fn the_point_addition_grows_and_reinitialises_the_set_mid_run() {
    let Some(ctx) = gpu() else { return };
    let mut rng = SplitMix64::new(21);
    let scene = defocus_scene(&mut rng);
    let init = noisy_init(&scene.truth, 1, &mut rng);
    let config = TrainConfig {
        iterations: 10,
        max_sh_degree: 0,
        seed: 3,
        loss_every: 1,
        densify: Some(DensifyConfig {
            from_iter: 1000,
            add_points_at: 5,
            add_points_count: 300,
            ..DensifyConfig::deblur()
        }),
        ..TrainConfig::default()
    };
    let mut trainer = Trainer::new(ctx, &init, &scene.train, config.clone()).unwrap();
    for _ in 0..5 {
        trainer.step().unwrap();
    }
    let g = trainer.gaussians().unwrap();
    assert!(
        g.len() > init.len() + 100,
        "{} Gaussians after adding up to 300 to {}",
        g.len(),
        init.len()
    );
    let logit = cocog_train::inverse_sigmoid(0.1);
    assert!(g.opacity_logits.iter().all(|o| (o - logit).abs() < 1e-6));
    assert!(g.quats.iter().all(|q| *q == [1.0, 0.0, 0.0, 0.0]));
    assert!(g.log_scales.iter().all(|s| s[0] == s[1] && s[1] == s[2]));
    // The rebuilt optimizer's first step is Adam's step 1, m̂ = g and v̂ = g²: every opacity
    // with a gradient moves by exactly its learning rate. Counting on from iteration 1, Adam
    // moves it 0.52× that here (step 6) and 3.0× at the default's 2500. A resumed run must
    // count the same way.
    let state = trainer.snapshot(1).unwrap();
    let mut resumed = Trainer::resume(ctx, &state, &scene.train, config.clone()).unwrap();
    // A checkpoint from before the origin was saved: the schedule says the rebuild happened.
    let older = cocog_train::TrainState {
        adam_origin: None,
        ..state.clone()
    };
    let mut inferred = Trainer::resume(ctx, &older, &scene.train, config.clone()).unwrap();
    for t in [&mut trainer, &mut resumed, &mut inferred] {
        t.step().unwrap();
        first_update_is_the_learning_rate(&g.opacity_logits, &t.gaussians().unwrap(), &config);
    }
    let mut readings = Vec::new();
    for _ in 0..4 {
        readings.extend(trainer.step().unwrap().readings);
    }
    readings.extend(trainer.finish().unwrap());
    assert!(!readings.is_empty() && readings.iter().all(|r| r.loss.is_finite()));
}

fn first_update_is_the_learning_rate(before: &[f32], after: &GaussianParams, c: &TrainConfig) {
    let moved: Vec<f32> = before
        .iter()
        .zip(&after.opacity_logits)
        .map(|(b, a)| (a - b).abs())
        .filter(|&d| d > 0.0)
        .collect();
    assert!(moved.len() > 50, "{} opacities moved", moved.len());
    let lr = c.opacity_lr;
    let off: Vec<f32> = moved
        .into_iter()
        .filter(|d| (d - lr).abs() > 1e-5)
        .collect();
    assert!(off.is_empty(), "opacity steps other than {lr}: {off:?}");
}
