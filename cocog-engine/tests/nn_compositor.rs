//! The compositor F and the softmax compositing: the f64 reference against central finite
//! differences for every parameter of every layer and every render value, then the GPU against
//! the reference per scalar, in both modes.

mod common;

use cocog_engine::GpuContext;
use cocog_engine::nn::reference::{
    Maps, Stored, backward, composite, composite_backward, forward, forward_from_stored,
    stored_from,
};
use cocog_engine::nn::{
    CompositeMode, Compositor, CompositorConfig, CompositorLayout, ConvPath, MapPrecision,
};
use cocog_engine::{Workspace, test_gpu};
use common::Rng;

const STEP: f64 = 1e-6;

fn random_maps(
    rng: &mut Rng,
    images: usize,
    channels: usize,
    h: usize,
    w: usize,
    lo: f64,
    hi: f64,
) -> Maps {
    let mut m = Maps::zeros(images, channels, h, w);
    for v in &mut m.data {
        *v = rng.range(lo, hi);
    }
    m
}

/// Parameters with larger weights than PyTorch's default, so logits differ across renders by
/// O(1) and the softmax weights are far from uniform; biases shifted so some ReLUs are off.
fn params(layout: &CompositorLayout, rng: &mut Rng) -> Vec<f64> {
    (0..layout.len)
        .map(|i| {
            let bias = (layout.conv1_b..layout.conv2_w).contains(&i)
                || (layout.conv2_b..layout.head_w).contains(&i);
            if bias {
                rng.range(-0.3, 0.1)
            } else {
                rng.range(-0.5, 0.5)
            }
        })
        .collect()
}

/// A loss with a distinct weight per composite value.
fn probe(blend: &Maps, coef: &Maps) -> f64 {
    blend.data.iter().zip(&coef.data).map(|(a, b)| a * b).sum()
}

fn check(what: &str, analytic: f64, fd: f64) {
    assert!(
        (analytic - fd).abs() <= 1e-6 + 1e-4 * fd.abs(),
        "{what}: analytic {analytic:e} vs finite difference {fd:e}"
    );
}

#[test]
fn reference_matches_finite_differences() {
    let mut rng = Rng::new(9);
    let layout = CompositorLayout::new(4);
    let (images, h, w) = (3, 7, 9);
    let renders = random_maps(&mut rng, images, 3, h, w, 0.0, 1.0);
    let coef = random_maps(&mut rng, 1, 3, h, w, -1.0, 1.0);
    let p = params(&layout, &mut rng);
    let t = forward(&layout, &p, &renders);
    let b = backward(&layout, &p, &t, &coef);
    let (v_renders, v_p) = (b.v_renders, b.v_params);
    let spread = t.weights.data.iter().cloned().fold(0.0, f64::max);
    assert!(
        spread > 0.5,
        "the softmax must be far from uniform: largest weight {spread}"
    );

    for i in 0..layout.len {
        let f = |x: f64| {
            let mut q = p.clone();
            q[i] = x;
            probe(&forward(&layout, &q, &renders).blend, &coef)
        };
        let fd = (f(p[i] + STEP) - f(p[i] - STEP)) / (2.0 * STEP);
        check(&format!("parameter {i}"), v_p[i], fd);
    }
    // The renders' gradient goes through the product only (F's input is detached): hold the
    // weights fixed while differencing the renders.
    for i in 0..renders.data.len() {
        let f = |x: f64| {
            let mut r = renders.clone();
            r.data[i] = x;
            let (_, blend) = composite(&r, &logits_of(&t.weights));
            probe(&blend, &coef)
        };
        let fd = (f(renders.data[i] + STEP) - f(renders.data[i] - STEP)) / (2.0 * STEP);
        check(&format!("render value {i}"), v_renders.data[i], fd);
    }
}

/// Logits that reproduce `weights` under the softmax (log of the weights).
fn logits_of(weights: &Maps) -> Maps {
    let mut l = weights.clone();
    for v in &mut l.data {
        *v = v.ln();
    }
    l
}

/// The compositing alone: softmax logits' gradient against finite differences.
#[test]
fn softmax_compositing_matches_finite_differences() {
    let mut rng = Rng::new(4);
    let (images, h, w) = (5, 3, 4);
    let renders = random_maps(&mut rng, images, 3, h, w, 0.0, 1.0);
    let logits = random_maps(&mut rng, images, 1, h, w, -2.0, 2.0);
    let coef = random_maps(&mut rng, 1, 3, h, w, -1.0, 1.0);
    let (weights, blend) = composite(&renders, &logits);
    let (_, v_logits) = composite_backward(&renders, &weights, &blend, &coef);
    for i in 0..logits.data.len() {
        let f = |x: f64| {
            let mut l = logits.clone();
            l.data[i] = x;
            probe(&composite(&renders, &l).1, &coef)
        };
        let fd = (f(logits.data[i] + STEP) - f(logits.data[i] - STEP)) / (2.0 * STEP);
        check(&format!("logit {i}"), v_logits.data[i], fd);
    }
}

fn to_rgba(m: &Maps) -> Vec<f32> {
    let (n, h, w) = (m.images, m.height, m.width);
    let mut out = vec![0.0f32; n * h * w * 4];
    for i in 0..n {
        for y in 0..h {
            for x in 0..w {
                for c in 0..3 {
                    out[((i * h + y) * w + x) * 4 + c] = m.at(i, c, y, x) as f32;
                }
                out[((i * h + y) * w + x) * 4 + 3] = 1.0;
            }
        }
    }
    out
}

/// `gpu_case_on` for each way of running the convolutions (the first layer's forward as an
/// implicit GEMM and, with Winograd, as its own kernel), with all renders through F
/// at once and in chunks of two (a binding that holds two renders' maps: F's maps of more
/// renders would outgrow it), storing F's maps in f32 and, where the adapter has it, f16.
///
/// The GPU is checked layer by layer: each stored map must be the exact layer applied to the
/// GPU's map before it (within f32 rounding, or its f16 rounding: with f16 maps the reference
/// cannot follow the GPU's roundings, as a value near a rounding boundary goes either way and a
/// flip propagates), and the composite and every gradient must be the reference's computed from
/// the GPU's maps, so that a gradient's budget covers the backward's rounding alone, not the
/// forward's carried through it. Chunked runs recompute the same maps, so they are checked
/// against the unchunked run's.
fn gpu_case(mode: CompositeMode, channels: usize, images: usize, h: usize, w: usize, seed: u64) {
    let Some(ctx) = test_gpu() else { return };
    let two = CompositorConfig::with_channels(channels as u32).map_bytes((h * w) as u64, 2);
    let mut precisions = vec![MapPrecision::F32];
    if ctx.shader_f16 {
        precisions.push(MapPrecision::F16);
    } else {
        eprintln!(
            "{}: no SHADER_F16, the f16 maps are not tested",
            ctx.adapter_name()
        );
    }
    for precision in precisions {
        let paths = [
            (ConvPath::Gemm, false),
            (ConvPath::Tiled, false),
            (ConvPath::Winograd, false),
            (ConvPath::Winograd, true),
        ];
        for (path, direct) in paths {
            let case = (path, direct, precision, mode);
            let maps = gpu_case_on(case, None, None, channels, images, h, w, seed);
            gpu_case_on(case, Some(two), maps.as_ref(), channels, images, h, w, seed);
        }
    }
}

/// The GPU's stored maps of every render, as f64.
fn read_stored(
    ctx: &GpuContext,
    bufs: [&cocog_engine::GpuBuffer; 4],
    precision: MapPrecision,
    (images, channels, h, w): (usize, usize, usize, usize),
) -> Stored {
    let n = images * channels * h * w;
    bufs.map(|b| {
        let data: Vec<f64> = match precision {
            MapPrecision::F32 => ctx
                .read::<f32>(b, n)
                .unwrap()
                .into_iter()
                .map(f64::from)
                .collect(),
            // Read as words: a copy moves multiples of 4 bytes.
            MapPrecision::F16 => {
                let words: Vec<u32> = ctx.read(b, n.div_ceil(2)).unwrap();
                let halves: &[u16] = bytemuck::cast_slice(&words);
                halves[..n]
                    .iter()
                    .map(|&v| half::f16::from_bits(v).to_f64())
                    .collect()
            }
        };
        Maps {
            images,
            channels,
            height: h,
            width: w,
            data,
        }
    })
}

/// Each of the GPU's f16 maps against the f16 rounding of the exact layer applied to the map
/// before it, per scalar: a conversion to f16 lands on one of the two neighbouring values (WGSL
/// leaves the rounding mode to the device), within an ulp (2⁻¹⁰ relative; below f16's normal
/// range, whose subnormals a device may flush, within its smallest normal 2⁻¹⁴) of the f32
/// value the GPU computed, itself within f32 rounding (1e-6 of the map's largest value) of
/// the exact one.
fn check_stored_f16(got: &Stored, want: &Stored) {
    for (layer, (g, x)) in got.iter().zip(want).enumerate() {
        let largest = x.data.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let mut rounded_away = 0;
        for (j, (&gv, &xv)) in g.data.iter().zip(&x.data).enumerate() {
            let tol = 2f64.powi(-10) * xv.abs() + 2f64.powi(-14) + 1e-6 * largest;
            assert!(
                (gv - xv).abs() <= tol,
                "stored map {layer}, value {j}: GPU {gv:e} vs exact {xv:e}"
            );
            rounded_away += usize::from(gv != xv);
        }
        // The maps really are f16: nearly every value moved off the exact one.
        assert!(
            rounded_away * 2 > x.data.len(),
            "stored map {layer}: only {rounded_away} of {} values rounded",
            x.data.len()
        );
    }
}

/// Each of the GPU's f32 maps against the exact layer applied to the map before it, per
/// scalar: within f32 rounding of the sums (a few ulps of the map's largest value and of the
/// value itself), so a layer's error cannot hide in the composite's tolerance.
fn check_stored_f32(got: &Stored, want: &Stored) {
    for (layer, (g, x)) in got.iter().zip(want).enumerate() {
        let largest = x.data.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        for (j, (&gv, &xv)) in g.data.iter().zip(&x.data).enumerate() {
            let tol = 1e-6 * xv.abs() + 1e-6 * largest;
            assert!(
                (gv - xv).abs() <= tol,
                "stored map {layer}, value {j}: GPU {gv:e} vs exact {xv:e}"
            );
        }
    }
}

/// One run, checked against the reference; returns the run's stored maps when it ran
/// unchunked in learned mode. `given`: an unchunked run's maps, which a chunked f16 run
/// recomputes.
#[allow(clippy::too_many_arguments)]
fn gpu_case_on(
    (path, direct, precision, mode): (ConvPath, bool, MapPrecision, CompositeMode),
    limit: Option<u64>,
    given: Option<&Stored>,
    channels: usize,
    images: usize,
    h: usize,
    w: usize,
    seed: u64,
) -> Option<Stored> {
    let ctx = test_gpu()?;
    let mut rng = Rng::new(seed);
    let layout = CompositorLayout::new(channels);
    // f32-representable inputs, so both sides start from the same numbers.
    let round = |m: &mut Maps| m.data.iter_mut().for_each(|v| *v = f64::from(*v as f32));
    let mut renders = random_maps(&mut rng, images, 3, h, w, 0.0, 1.0);
    let mut coef = random_maps(&mut rng, 1, 3, h, w, -1.0, 1.0);
    round(&mut renders);
    round(&mut coef);
    let p: Vec<f64> = params(&layout, &mut rng)
        .iter()
        .map(|v| f64::from(*v as f32))
        .collect();

    let config = CompositorConfig::with_channels(channels as u32);
    let mut comp =
        Compositor::with_options(ctx, config, path, precision).with_direct_first_forward(direct);
    if let Some(bytes) = limit {
        comp = comp.with_binding_limit(bytes);
    }
    let p32: Vec<f32> = p.iter().map(|v| *v as f32).collect();
    let params_buf = ctx.storage_from("params", &p32);
    let renders_buf = ctx.storage_from("renders", &to_rgba(&renders));
    let v_blend_buf = ctx.storage_from("v blend", &to_rgba(&coef));
    let mut ws = Workspace::default();
    let mut rec = ctx.recorder();
    let (wu, hu, nu) = (w as u32, h as u32, images as u32);
    let out = comp.encode_forward(
        &mut rec,
        &mut ws,
        &params_buf,
        &renders_buf,
        wu,
        hu,
        nu,
        mode,
    );
    let g = comp.encode_backward(
        &mut rec,
        &mut ws,
        &params_buf,
        &renders_buf,
        &out,
        &v_blend_buf,
    );
    rec.submit();
    let blend: Vec<f32> = ctx.read(&out.blend, h * w * 4).unwrap();
    let v_renders: Vec<f32> = ctx.read(&g.v_renders, images * h * w * 4).unwrap();
    let v_p: Vec<f32> = ctx.read(&g.v_params, layout.len).unwrap();
    let stored = match (limit, out.stored_maps()) {
        (None, Some(bufs)) => Some(read_stored(ctx, bufs, precision, (images, channels, h, w))),
        _ => None,
    };

    let (want_blend, want_v_renders, want_v_p, bounds) = match mode {
        CompositeMode::Learned => {
            let maps = given.or(stored.as_ref()).expect("an unchunked run's maps");
            if given.is_none() {
                let exact = stored_from(&layout, &p, &renders, maps);
                match precision {
                    MapPrecision::F32 => check_stored_f32(maps, &exact),
                    MapPrecision::F16 => check_stored_f16(maps, &exact),
                }
            }
            let t = forward_from_stored(&layout, &p, &renders, maps);
            let b = backward(&layout, &p, &t, &coef);
            (t.blend, b.v_renders, b.v_params, b.bounds)
        }
        CompositeMode::Uniform => {
            let zero = Maps::zeros(images, 1, h, w);
            let (weights, blend) = composite(&renders, &zero);
            let (vr, _) = composite_backward(&renders, &weights, &blend, &coef);
            (blend, vr, vec![0.0; layout.len], vec![0.0; layout.len])
        }
    };
    let close = |what: &str, got: f32, want: f64, tol: f64| {
        assert!(
            (f64::from(got) - want).abs() <= tol,
            "{path:?} (direct first forward: {direct}), {precision:?}, binding {limit:?}: {what}: GPU {got:e} vs reference {want:e}"
        );
    };
    for y in 0..h {
        for x in 0..w {
            for c in 0..3 {
                close(
                    "blend",
                    blend[(y * w + x) * 4 + c],
                    want_blend.at(0, c, y, x),
                    1e-5,
                );
            }
            for i in 0..images {
                for c in 0..3 {
                    let got = v_renders[((i * h + y) * w + x) * 4 + c];
                    close("v render", got, want_v_renders.at(i, c, y, x), 1e-5);
                }
            }
        }
    }
    // Each parameter's own budget: f32 rounding of its final sum scales with Σ|term| (the
    // reference reports it), and its inputs carry rounding from the backward's layers above
    // (the forward's maps are the GPU's own). The largest error on lavapipe was 0.74 of it.
    let mut checked = 0;
    for (i, (&got, &want)) in v_p.iter().zip(&want_v_p).enumerate() {
        close(
            &format!("v param {i}"),
            got,
            want,
            1e-4 * want.abs() + 2e-5 * bounds[i] + 1e-9,
        );
        checked += usize::from(want.abs() > 1e-3);
    }
    if mode == CompositeMode::Learned {
        assert!(
            checked > layout.len / 2,
            "too few non-trivial gradients: {checked}"
        );
    }
    stored
}

/// The first layer's forward by its own kernel by default on a GPU, where it beat the implicit
/// GEMM on an H100, and as the GEMM on a CPU adapter, where it is the slower (session 42).
#[test]
fn gpu_first_layer_forward_defaults_by_adapter() {
    let Some(ctx) = test_gpu() else { return };
    if std::env::var_os("COCOG_F_FIRST").is_some() {
        eprintln!("skipped: COCOG_F_FIRST is set");
        return;
    }
    assert_eq!(cocog_engine::nn::direct_first_forward(ctx), !ctx.is_cpu());
}

/// `cocog bench` reports F's path from the kernels a compositor built and the passes that use
/// them, not from the switches.
#[test]
fn gpu_compositor_describes_the_kernels_it_runs() {
    let Some(ctx) = test_gpu() else { return };
    let said = |channels, path, direct| {
        let config = CompositorConfig::with_channels(channels);
        Compositor::with_options(ctx, config, path, MapPrecision::F32)
            .with_direct_first_forward(direct)
            .describe()
    };
    assert_eq!(
        said(32, ConvPath::Winograd, true),
        "3×3 layer by Winograd F(2×2, 3×3), the first layer's forward direct"
    );
    assert_eq!(
        said(32, ConvPath::Winograd, false),
        "3×3 layer by Winograd F(2×2, 3×3), the first layer's forward as an implicit GEMM"
    );
    // Below 32 channels the 3×3 layer's passes take the GEMMs; the first layer keeps its own.
    assert_eq!(
        said(8, ConvPath::Winograd, true),
        "implicit GEMMs, the first layer's forward direct"
    );
    assert_eq!(said(32, ConvPath::Gemm, true), "implicit GEMMs");
    assert_eq!(
        said(8, ConvPath::Tiled, false),
        "tiled convolutions (COCOG_F_CONV=tiled)"
    );
    // Without cooperative matrices enabled, coop runs the f32 tiles, and says so.
    if ctx.cooperative.is_none() {
        assert_eq!(said(8, ConvPath::Coop, false), "implicit GEMMs");
    }
}

#[test]
fn gpu_learned_mode_matches_the_reference() {
    gpu_case(CompositeMode::Learned, 8, 3, 7, 9, 5);
}

/// The real width, and a size whose pixel count is not a multiple of the 256-wide workgroups.
#[test]
fn gpu_learned_mode_at_full_width_matches_the_reference() {
    gpu_case(CompositeMode::Learned, 64, 5, 12, 17, 6);
}

/// Maps of an odd number of values (3 channels of 5×7 pixels, 3 renders): the last f16 shares
/// its word with nothing.
#[test]
fn gpu_learned_mode_with_odd_sized_maps_matches_the_reference() {
    gpu_case(CompositeMode::Learned, 3, 3, 5, 7, 10);
}

#[test]
fn gpu_uniform_mode_is_the_mean() {
    gpu_case(CompositeMode::Uniform, 8, 5, 6, 5, 7);
}

/// More channels than one 64-row tile of the convolutions' matrix products.
#[test]
fn gpu_learned_mode_past_one_channel_block_matches_the_reference() {
    gpu_case(CompositeMode::Learned, 72, 3, 9, 8, 8);
}

/// Two channel blocks, and maps of more than one Winograd workgroup's 8×8 output tiles along
/// both sides (10 × 9 tiles), the last ones cut by the map's odd height.
#[test]
fn gpu_learned_mode_past_one_block_of_tiles_matches_the_reference() {
    gpu_case(CompositeMode::Learned, 72, 2, 19, 18, 11);
}

/// 66 channels: the first layer's weight gradient has a second block of output channels, not a
/// multiple of four, and the Winograd weight sum a last workgroup of channel pairs short
/// (66² = 4356 pairs, 4 past a multiple of its 16).
#[test]
fn gpu_learned_mode_with_ragged_channel_blocks_matches_the_reference() {
    gpu_case(CompositeMode::Learned, 66, 2, 11, 9, 13);
}

/// More tiles than the Winograd weight gradient's ranges take in one slice each (4232 tiles in
/// 89 ranges of 48, 3 slices), the last range short.
#[test]
fn gpu_learned_mode_with_ranges_of_several_slices_matches_the_reference() {
    gpu_case(CompositeMode::Learned, 32, 2, 92, 92, 12);
}

/// Maps large enough that the head's weight gradient splits 327,680 positions into 1024 ranges
/// of 320 (more ranges than a summing workgroup has threads, longer than the 256 minimum).
#[test]
fn gpu_learned_mode_with_a_thousand_ranges_matches_the_reference() {
    gpu_case(CompositeMode::Learned, 4, 5, 256, 256, 9);
}
