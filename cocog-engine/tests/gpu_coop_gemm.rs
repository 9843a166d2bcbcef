//! The experimental cooperative-matrix product (`CoopGemm`). Everywhere: its WGSL compiles to
//! SPIR-V through naga (what wgpu runs on Vulkan), which caught a naga 30 bug that drops
//! expressions written inside a `coopStore` call. Where an adapter has 16×16×16 f16→f32
//! cooperative matrices (NVIDIA's tensor cores; no software adapter has them): with
//! `COCOG_COOPERATIVE_MATRIX=1`, the product against an f64 one of the same f16 inputs.

mod common;

use cocog_engine::CoopGemm;
use common::{Rng, gpu};

#[test]
fn coop_gemm_compiles_to_spirv() {
    let source = CoopGemm::wgsl();
    let module = naga::front::wgsl::parse_str(&source)
        .unwrap_or_else(|e| panic!("{}", e.emit_to_string(&source)));
    let info = naga::valid::Validator::new(
        naga::valid::ValidationFlags::all(),
        naga::valid::Capabilities::all(),
    )
    .validate(&module)
    .expect("valid module");
    let options = naga::back::spv::Options {
        lang_version: (1, 5),
        ..Default::default()
    };
    let words = naga::back::spv::write_vec(&module, &info, &options, None).expect("SPIR-V");
    assert_eq!(words[0], 0x0723_0203, "SPIR-V magic");
}

#[test]
fn coop_gemm_matches_f64_where_the_adapter_has_tensor_cores() {
    let Some(ctx) = gpu() else { return };
    let Some(gemm) = CoopGemm::new(ctx) else {
        // Asked for, on an adapter that offers the shape: only a subgroup width other than 32
        // may refuse it, and that must not read as a pass on a GPU with tensor cores.
        let asked = std::env::var("COCOG_COOPERATIVE_MATRIX").is_ok_and(|v| v == "1");
        let offered = ctx.cooperative_matrix_shapes().contains("16×16×16 f16→f32");
        assert!(
            !(asked && offered && ctx.adapter_info.subgroup_min_size == 32),
            "COCOG_COOPERATIVE_MATRIX=1 and {} offers 16×16×16 f16→f32, but the context did \
             not enable it",
            ctx.adapter_name()
        );
        eprintln!(
            "skipped: {} has no 16×16×16 f16→f32 cooperative matrices enabled (offers: {}; \
             COCOG_COOPERATIVE_MATRIX=1 enables them where offered)",
            ctx.adapter_name(),
            ctx.cooperative_matrix_shapes()
        );
        return;
    };
    let (m, n, k) = (128usize, 192usize, 96usize);
    let mut rng = Rng::new(7);
    let mut half = |len: usize| -> Vec<half::f16> {
        (0..len)
            .map(|_| half::f16::from_f32(rng.range_f32(-1.0, 1.0)))
            .collect()
    };
    let (a, b) = (half(m * k), half(k * n));
    let bits = |v: &[half::f16]| v.iter().map(|h| h.to_bits()).collect::<Vec<u16>>();
    let ga = ctx.storage_from("a", &bits(&a));
    let gb = ctx.storage_from("b", &bits(&b));
    let gc = ctx.storage("c", (m * n * 4) as u64);
    let mut rec = ctx.recorder();
    gemm.encode(&mut rec, (m as u32, n as u32, k as u32), &ga, &gb, &gc);
    rec.submit();
    let got: Vec<f32> = ctx.read(&gc, m * n).expect("read C");
    for i in 0..m {
        for j in 0..n {
            let (mut want, mut mag) = (0.0f64, 0.0f64);
            for kk in 0..k {
                let p = f64::from(a[i * k + kk].to_f32()) * f64::from(b[kk * n + j].to_f32());
                want += p;
                mag += p.abs();
            }
            let g = f64::from(got[i * n + j]);
            // f16 × f16 is exact in f32; the error is the f32 accumulation's.
            let tol = 1e-5 * mag + 1e-6;
            assert!(
                (g - want).abs() <= tol,
                "C[{i}][{j}] = {g}, want {want} (±{tol})"
            );
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
fn compositor_on_tensor_cores_matches_the_f32_products() {
    use cocog_engine::Workspace;
    use cocog_engine::nn::{CompositeMode, Compositor, CompositorConfig, ConvPath, MapPrecision};
    let Some(ctx) = gpu() else { return };
    if !ctx.cooperative_f16 {
        eprintln!(
            "skipped: {} has no cooperative matrices enabled (COCOG_COOPERATIVE_MATRIX=1 where \
             16×16×16 f16→f32 is offered; offers: {})",
            ctx.adapter_name(),
            ctx.cooperative_matrix_shapes()
        );
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
