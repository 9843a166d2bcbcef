//! The experimental product on cooperative matrices (`Gemm::cooperative`), where an adapter
//! has square f16→f32 ones (NVIDIA's tensor cores: 16×16×16; lavapipe in Mesa 26.2: 8×8×8)
//! and `COCOG_COOPERATIVE_MATRIX=1` enables them: on plain matrices against an f64 product of
//! the same f16-representable inputs, and as F's convolutions against the f32 products. Its WGSL
//! is compiled to SPIR-V everywhere by conv_gemm's unit test.

mod common;

use cocog_engine::{
    CoopBlock, CoopFragments, Gemm, GemmLayout, GemmShape, GemmTile, OperandScales, Workspace,
};
use common::{Rng, gpu, plain_gemm_problem, run_gemm};

/// Prints why the test does not run; fails instead where it was asked for
/// (`COCOG_COOPERATIVE_MATRIX=1`) on an adapter that offers what the kernel needs, so a context
/// that wrongly declines cannot read as a pass on a GPU with tensor cores.
fn skip_unless_refused(ctx: &cocog_engine::GpuContext) {
    let asked = std::env::var("COCOG_COOPERATIVE_MATRIX").is_ok_and(|v| v == "1");
    let info = &ctx.adapter_info;
    let usable = CoopFragments::choose(
        &ctx.cooperative_matrices,
        info.subgroup_min_size,
        info.subgroup_max_size,
    );
    assert!(
        !(asked && ctx.shader_f16 && usable.is_some()),
        "COCOG_COOPERATIVE_MATRIX=1 and {} offers {usable:?}, but the context did not enable \
         cooperative matrices",
        ctx.adapter_name()
    );
    eprintln!(
        "skipped: {} has no square f16→f32 cooperative matrices enabled (offers: {}; subgroups \
         {}..={} wide; COCOG_COOPERATIVE_MATRIX=1 enables 16×16×16 or 8×8×8 where subgroups have \
         one width)",
        ctx.adapter_name(),
        ctx.cooperative_matrix_shapes(),
        info.subgroup_min_size,
        info.subgroup_max_size,
    );
}

#[test]
fn cooperative_product_matches_f64_where_the_adapter_has_them() {
    let Some(ctx) = gpu() else { return };
    let Some(fragments) = ctx.cooperative else {
        skip_unless_refused(ctx);
        return;
    };
    let mut ran = 0;
    for (name, block) in CoopBlock::NAMED {
        if !Gemm::fits(ctx, block, fragments) {
            eprintln!(
                "block {name}: {block:?} does not fit {}",
                ctx.adapter_name()
            );
            continue;
        }
        product_matches_f64(ctx, name, block);
        ran += 1;
    }
    // The first layout is the default and must run everywhere.
    assert!(ran > 0 && Gemm::fits(ctx, CoopBlock::SQUARE, fragments));
}

/// One block layout on plain matrices, in every operand order without split K and in both
/// orders of B with it (F's weight gradients: B contiguous along K). Sizes off every block
/// (64 × 64 × 32 on 16-wide fragments, 32 × 32 × 16 on 8-wide, and the wider ones), so edges
/// are padded; split K sums 3 batches in parts.
fn product_matches_f64(ctx: &cocog_engine::GpuContext, name: &str, block: CoopBlock) {
    let plain_size = (70, 130, 45, 2);
    let split_size = (20, 33, 700, 3);
    for (a_k_fast, b_k_fast, split_k, (m, n, k, batches)) in [
        (true, false, false, plain_size),
        (true, true, false, plain_size),
        (false, false, false, plain_size),
        (false, true, false, plain_size),
        (true, false, true, split_size),
        (true, true, true, split_size),
    ] {
        let layout = GemmLayout {
            a_k_fast,
            b_k_fast,
            split_k,
            ones_column: false,
            tile: GemmTile::SQUARE,
        };
        let scales = OperandScales { a: 4.0, b: 0.5 };
        let gemm = Gemm::cooperative_with(
            ctx,
            "coop test",
            &plain_gemm_problem(layout, 0.0),
            layout,
            scales,
            block,
        )
        .expect("cooperative matrices enabled");
        let mut rng = Rng::new(7);
        // f16-representable inputs, so the f64 product sees what the tensor cores multiply.
        let mut half = |len: usize| -> Vec<f32> {
            (0..len)
                .map(|_| half::f16::from_f32(rng.range_f32(-1.0, 1.0)).to_f32())
                .collect()
        };
        let (a, b) = (half(batches * m * k), half(batches * k * n));
        let outputs = if split_k { 1 } else { batches };
        let shape = GemmShape {
            m: m as u32,
            n: n as u32,
            k: k as u32,
            batches: batches as u32,
            ..Default::default()
        };
        let got = run_gemm(ctx, &gemm, shape, &a, &b, outputs);
        for o in 0..outputs {
            let summed = if split_k { 0..batches } else { o..o + 1 };
            for i in 0..m {
                for j in 0..n {
                    let (mut want, mut mag) = (0.0f64, 0.0f64);
                    for bt in summed.clone() {
                        for kk in 0..k {
                            let ai = if a_k_fast {
                                (bt * m + i) * k + kk
                            } else {
                                (bt * k + kk) * m + i
                            };
                            let bi = if b_k_fast {
                                (bt * n + j) * k + kk
                            } else {
                                (bt * k + kk) * n + j
                            };
                            let p = f64::from(a[ai]) * f64::from(b[bi]);
                            want += p;
                            mag += p.abs();
                        }
                    }
                    let g = f64::from(got[(o * m + i) * n + j]);
                    // f16 × f16 is exact in f32 (and the power-of-two scales are exact); the
                    // error is the f32 accumulation's.
                    let tol = 1e-5 * mag + 1e-6;
                    assert!(
                        (g - want).abs() <= tol,
                        "block {name}, A k-fast {a_k_fast}, B k-fast {b_k_fast}, split {split_k}: \
                         C[{o}][{i}][{j}] = {g}, want {want} (±{tol})"
                    );
                }
            }
        }
    }
}

/// F with its convolutions on tensor cores (`ConvPath::Coop`) against F on the f32 implicit
/// GEMMs (which nn_compositor checks against f64), per scalar. f16 operands cost about three
/// decimal digits; a ReLU whose input sits near zero would turn that into a different mask, so
/// the parameters keep every pre-activation well above zero (weights small, biases positive).
/// The composite, and each layer's parameter gradient, must agree within 1% of its own largest
/// value, which a wrong index, block or layout misses by far. The loss gradient is 1e-6 per
/// value, as a real one over a frame: unscaled, its products would fall to f16's subnormals and
/// miss too. 80 channels and 26×24 pixels give two row blocks and several split-K parts.
#[test]
fn compositor_on_cooperative_matrices_matches_the_f32_products() {
    use cocog_engine::nn::{CompositeMode, Compositor, CompositorConfig, ConvPath, MapPrecision};
    let Some(ctx) = gpu() else { return };
    if ctx.cooperative.is_none() {
        skip_unless_refused(ctx);
        return;
    }
    let (channels, images, h, w) = (80u32, 3u32, 26u32, 24u32);
    let config = CompositorConfig::with_channels(channels);
    let l = config.layout();
    let mut rng = Rng::new(11);
    let params: Vec<f32> = (0..l.len)
        .map(|i| {
            if (l.conv1_b..l.conv2_w).contains(&i) || (l.conv2_b..l.head_w).contains(&i) {
                rng.range_f32(1.0, 1.5)
            } else if i < l.conv1_b {
                rng.range_f32(-0.05, 0.05)
            } else {
                rng.range_f32(-0.02, 0.02)
            }
        })
        .collect();
    let pixels = (images * h * w) as usize;
    let renders: Vec<f32> = (0..pixels * 4).map(|_| rng.range_f32(0.0, 1.0)).collect();
    let v_blend: Vec<f32> = (0..(h * w) as usize * 4)
        .map(|_| rng.range_f32(-1e-6, 1e-6))
        .collect();
    let run = |path| {
        let comp = Compositor::with_options(ctx, config, path, MapPrecision::F32);
        let p = ctx.storage_from("params", &params);
        let r = ctx.storage_from("renders", &renders);
        let v = ctx.storage_from("v blend", &v_blend);
        let mut ws = Workspace::default();
        let mut rec = ctx.recorder();
        let mode = CompositeMode::Learned;
        let out = comp.encode_forward(&mut rec, &mut ws, &p, &r, w, h, images, mode);
        let g = comp.encode_backward(&mut rec, &mut ws, &p, &r, &out, &v);
        rec.submit();
        (
            ctx.read::<f32>(&out.blend, (h * w) as usize * 4).unwrap(),
            ctx.read::<f32>(&g.v_params, l.len).unwrap(),
        )
    };
    let (exact, coop) = (run(ConvPath::Gemm), run(ConvPath::Coop));
    let parts = [
        ("composite", &exact.0[..], &coop.0[..]),
        // A bias before an instance norm has no gradient (the norm takes the plane's mean
        // away): its rounding noise is judged on its layer's weights' scale.
        ("conv1", &exact.1[..l.conv2_w], &coop.1[..l.conv2_w]),
        (
            "conv2",
            &exact.1[l.conv2_w..l.head_w],
            &coop.1[l.conv2_w..l.head_w],
        ),
        ("head", &exact.1[l.head_w..], &coop.1[l.head_w..]),
    ];
    for (what, e, c) in parts {
        let largest = e.iter().fold(0.0f32, |m, v| m.max(v.abs()));
        assert!(largest > 0.0, "{what}: all zero");
        for (j, (a, b)) in e.iter().zip(c).enumerate() {
            assert!(
                (a - b).abs() <= 1e-2 * largest,
                "{what} {j}: tensor cores {b:e} vs f32 {a:e} (largest {largest:e})"
            );
        }
    }
}
