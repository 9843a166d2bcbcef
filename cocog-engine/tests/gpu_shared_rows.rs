//! CoCoGaussian's sets share opacity and SH with their base (`ParamBuffers::shared_rows`):
//! rendering and differentiating sets that read the base's rows must give what sets holding
//! copies of those rows give, image for image and gradient row for gradient row.

mod common;

use cocog_engine::{Batch, GaussianParams, GpuContext, ImageSpec, ParamBuffers, Renderer};
use common::{Rng, gpu, random_scene, random_weights, test_camera};

const SETS: u32 = 3;

/// Three sets of `base`: moved and reshaped copies with the base's opacity and SH.
fn sets_of(base: &GaussianParams, rng: &mut Rng) -> Vec<GaussianParams> {
    (0..SETS)
        .map(|s| {
            let mut g = base.clone();
            if s > 0 {
                for m in &mut g.means {
                    m.iter_mut().for_each(|v| *v += rng.range_f32(-0.05, 0.05));
                }
                for l in &mut g.log_scales {
                    l.iter_mut().for_each(|v| *v += rng.range_f32(0.0, 0.1));
                }
            }
            g
        })
        .collect()
}

fn batch(ctx: &GpuContext, params: ParamBuffers, n: u32, cam: &cocog_engine::Camera) -> Batch {
    let specs = (0..SETS)
        .map(|s| ImageSpec {
            camera: *cam,
            background: [0.2, 0.1, 0.0],
            first: s * n,
            count: n,
            crop: None,
        })
        .collect();
    Batch::new(ctx, params, specs).unwrap()
}

#[test]
fn sets_reading_shared_rows_render_and_differentiate_like_copies() {
    let Some(ctx) = gpu() else { return };
    let cam = test_camera(40, 32, 0.1);
    let base = random_scene(80, 2, 7, &cam);
    let n = base.len() as u32;
    let sets = sets_of(&base, &mut Rng::new(8));
    let refs: Vec<&GaussianParams> = sets.iter().collect();
    let copies = batch(ctx, ParamBuffers::upload(ctx, &refs).unwrap(), n, &cam);
    let own = ParamBuffers::upload(ctx, &[&base]).unwrap();
    let all = ParamBuffers::upload(ctx, &refs).unwrap();
    let shared = ParamBuffers {
        opacity_logits: own.opacity_logits,
        sh: own.sh,
        shared_rows: n,
        ..all
    };
    let shared = batch(ctx, shared, n, &cam);

    let renderer = Renderer::new(ctx);
    let (sa, sb) = (
        renderer.forward(ctx, &copies).unwrap(),
        renderer.forward(ctx, &shared).unwrap(),
    );
    let (ia, ib) = (
        sa.read_images(ctx, &copies).unwrap(),
        sb.read_images(ctx, &shared).unwrap(),
    );
    assert_eq!(ia, ib, "the renders differ");
    // The sets do differ from one another, so each read its own means.
    assert_ne!(ia[0].color, ia[1].color);

    let npix = (40 * 32 * SETS) as usize;
    let (c, a, _) = random_weights(npix, 3);
    let v_rgba: Vec<[f32; 4]> = c
        .iter()
        .zip(&a)
        .map(|(c, &a)| [c[0] as f32, c[1] as f32, c[2] as f32, a as f32])
        .collect();
    let v_rgba = ctx.storage_from("v_rgba", &v_rgba);
    let ga = renderer.backward(ctx, &copies, &sa, &v_rgba, None);
    let gb = renderer.backward(ctx, &shared, &sb, &v_rgba, None);
    let total = SETS * n;
    let (ga, gb) = (
        ga.params.read_grads(ctx, 0, total).unwrap().scalars(),
        gb.params.read_grads(ctx, 0, total).unwrap().scalars(),
    );
    assert_eq!(ga.len(), gb.len());
    let scale = ga.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    assert!(scale > 0.0);
    for (k, (x, y)) in ga.iter().zip(&gb).enumerate() {
        // Only the order of the rasterizer's float atomics may differ.
        assert!(
            (x - y).abs() <= 1e-5 * x.abs() + 1e-7 * scale,
            "gradient scalar {k}: copies {x}, shared rows {y}"
        );
    }
}

#[test]
fn shared_rows_must_divide_the_gaussians() {
    let Some(ctx) = gpu() else { return };
    let cam = test_camera(16, 16, 0.0);
    let g = random_scene(10, 0, 1, &cam);
    let params = ParamBuffers {
        shared_rows: 4,
        ..ParamBuffers::upload(ctx, &[&g]).unwrap()
    };
    let spec = ImageSpec {
        camera: cam,
        background: [0.0; 3],
        first: 0,
        count: 10,
        crop: None,
    };
    let err = Batch::new(ctx, params, vec![spec]).unwrap_err().to_string();
    assert!(
        err.contains("10 Gaussians") && err.contains("sets of 4"),
        "{err}"
    );
}
