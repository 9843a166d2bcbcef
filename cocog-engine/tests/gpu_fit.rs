//! End to end on the GPU: forward → loss → backward → Adam, repeated, must pull a perturbed
//! scene towards the images of the original. Catches wiring mistakes (buffer layouts,
//! gradient signs) that the per-kernel tests cannot.

mod common;

use cocog_engine::{Adam, AdamConfig, AdamMoments, Batch, ImageLoss, Renderer, View};
use common::{Rng, gpu, random_scene, test_camera};

#[test]
fn optimising_all_parameters_reduces_the_loss() {
    let Some(ctx) = gpu() else { return };
    let cam = test_camera(64, 48, 0.1);
    let truth = random_scene(40, 1, 8, &cam);
    let mut start = truth.clone();
    let mut rng = Rng::new(99);
    for i in 0..start.len() {
        start.means[i]
            .iter_mut()
            .for_each(|v| *v += rng.range_f32(-0.05, 0.05));
        start.log_scales[i]
            .iter_mut()
            .for_each(|v| *v += rng.range_f32(-0.3, 0.3));
        start.opacity_logits[i] += rng.range_f32(-1.0, 1.0);
    }
    start
        .sh
        .iter_mut()
        .for_each(|v| *v += rng.range_f32(-0.3, 0.3));

    let renderer = Renderer::new(ctx);
    let loss = ImageLoss::new(ctx);
    let adam = Adam::new(ctx);
    let view = |g| View {
        gaussians: g,
        camera: &cam,
        background: [0.5; 3],
    };
    let truth_batch = Batch::from_views(ctx, &[view(&truth)]).unwrap();
    let target = renderer.forward(ctx, &truth_batch).unwrap().rgba;
    let batch = Batch::from_views(ctx, &[view(&start)]).unwrap();
    let p = &batch.params;
    let n = p.num_gaussians;
    let lens = [3 * n, 3 * n, 4 * n, n, 12 * n];
    let moments: Vec<AdamMoments> = lens.iter().map(|&len| AdamMoments::new(ctx, len)).collect();
    let configs = [0.002, 0.01, 0.01, 0.05, 0.01].map(AdamConfig::with_lr);
    let mut losses = Vec::new();
    for step in 1..=60 {
        let state = renderer.forward(ctx, &batch).unwrap();
        let mut rec = ctx.recorder();
        let mut ws = cocog_engine::Workspace::default();
        let out = loss
            .compute(&mut rec, &mut ws, &state.rgba, &target, 64, 48, 1, 0.2)
            .expect("loss");
        rec.submit();
        if step == 1 || step == 60 {
            losses.push(out.read_loss(ctx).unwrap());
        }
        let grads = renderer.backward(ctx, &batch, &state, &out.v_pred, None);
        let g = &grads.params;
        let pairs = [
            (&p.means, &g.means),
            (&p.log_scales, &g.log_scales),
            (&p.quats, &g.quats),
            (&p.opacity_logits, &g.opacity_logits),
            (&p.sh, &g.sh),
        ];
        let mut rec = ctx.recorder();
        for (k, (param, grad)) in pairs.into_iter().enumerate() {
            adam.encode(&mut rec, param, grad, &moments[k], &configs[k], step, None);
        }
        rec.submit();
    }
    eprintln!("loss {:.5} → {:.5}", losses[0], losses[1]);
    assert!(
        losses[1] < 0.5 * losses[0],
        "loss only went from {} to {}",
        losses[0],
        losses[1]
    );
}
