//! The CoC kernels against the f64 reference, per scalar: h_θ's heads, the M + 1 expanded
//! sets, the base gradients summed over the sets, every weight gradient of h_θ and the focus
//! distance's (and the lens variant's aperture's) gradient, for every variant at the real
//! width (64), in a normalised frame with an origin and a scale that are not 0 and 1, over
//! more Gaussians than one matrix-product tile or reduction part holds.

mod common;

use cocog_engine::coc::reference::{
    Base, Expanded, MlpTrace, expand, expand_backward, gate, input, mlp_backward, mlp_forward,
    variant_gate,
};
use cocog_engine::coc::{
    CAMERA_DIM, CocConfig, CocKernels, CocStep, CocVariant, MEAN_DIM, ROW_DIM, init_weights,
};
use cocog_engine::{GpuContext, Workspace, test_gpu};
use common::Rng;

/// More than one 1024-Gaussian chunk, not a multiple of the 64-wide workgroup.
const N: usize = 1100;
const VIEWS: usize = 3;
const VIEW: u32 = 1;
const CAMERA: [f64; 3] = [0.05, -0.02, -0.1];
/// The frame: world = ORIGIN + SCALE × normalised.
const ORIGIN: [f64; 3] = [0.3, -0.2, 0.5];
const SCALE: f64 = 2.0;
const APERTURES: [f32; 3] = [0.02, 0.05, 0.08];

fn to_world(p: [f64; 3]) -> [f64; 3] {
    [0, 1, 2].map(|k| ORIGIN[k] + SCALE * p[k])
}

struct Inputs {
    /// In the normalised frame (what the reference computes in).
    bases: Vec<Base>,
    weights: Vec<f32>,
    focus: Vec<f32>,
    /// Gradient of every expanded set in world units, `[set][base]`.
    v_sets: Vec<Expanded>,
}

fn inputs(config: &CocConfig, seed: u64) -> Inputs {
    let mut rng = Rng::new(seed);
    let mut weights = init_weights(&config.mlp(), seed);
    // Spread the heads over the multipliers' clamped and open ranges.
    let (_, fan_out, wo, bo) = config.mlp().layers[3];
    for v in &mut weights[wo..bo + fan_out] {
        *v *= 3.0;
    }
    // Values stored in f32 on the GPU: round them once so both sides start equal.
    let mut r = |lo: f64, hi: f64| f64::from(rng.range_f32(lo, hi));
    let bases = (0..N)
        .map(|_| Base {
            mean: [r(-0.5, 0.5), r(-0.4, 0.4), r(0.6, 3.5)],
            log_scale: [r(-4.0, -1.0), r(-4.0, -1.0), r(-4.0, -1.0)],
            quat: [r(0.3, 1.5), r(-0.6, 0.6), r(-0.6, 0.6), r(-0.6, 0.6)],
        })
        .collect();
    let sets = (config.copies as usize + 1) * N;
    let v_sets = (0..sets)
        .map(|_| Expanded {
            mean: [r(-1.0, 1.0), r(-1.0, 1.0), r(-1.0, 1.0)],
            log_scale: [r(-1.0, 1.0), r(-1.0, 1.0), r(-1.0, 1.0)],
            quat: [r(-1.0, 1.0), r(-1.0, 1.0), r(-1.0, 1.0), r(-1.0, 1.0)],
        })
        .collect();
    Inputs {
        bases,
        weights,
        focus: vec![0.45, 0.575, 0.7],
        v_sets,
    }
}

fn flat<const K: usize>(v: impl Iterator<Item = [f64; K]>) -> Vec<f32> {
    v.flat_map(|a| a.map(|x| x as f32)).collect()
}

fn close(what: &str, gpu: f32, reference: f64, tol: f64) {
    assert!(
        (f64::from(gpu) - reference).abs() <= tol,
        "{what}: GPU {gpu:e} vs reference {reference:e} (tolerance {tol:e})"
    );
}

struct Gpu {
    /// h_θ's input, hidden activations and heads, [Gaussian][width] each, as the backward
    /// replays them.
    acts: [Vec<f32>; 5],
    sets: [Vec<f32>; 3],
    v_base: [Vec<f32>; 3],
    v_weights: Vec<f32>,
    v_focus: Vec<f32>,
    v_aperture: Vec<f32>,
}

fn run_gpu(ctx: &GpuContext, config: CocConfig, inp: &Inputs) -> Gpu {
    let kernels = CocKernels::new(ctx, config);
    let means = ctx.storage_from("means", &flat(inp.bases.iter().map(|b| to_world(b.mean))));
    let log_scales = ctx.storage_from(
        "log-scales",
        &flat(
            inp.bases
                .iter()
                .map(|b| b.log_scale.map(|l| l + SCALE.ln())),
        ),
    );
    let quats = ctx.storage_from("quats", &flat(inp.bases.iter().map(|b| b.quat)));
    let weights = ctx.storage_from("weights", &inp.weights);
    let focus = ctx.storage_from("focus", &inp.focus);
    let apertures = ctx.storage_from("apertures", &APERTURES);
    let v_means = ctx.storage_from("v set means", &flat(inp.v_sets.iter().map(|v| v.mean)));
    let v_ls = ctx.storage_from(
        "v set log-scales",
        &flat(inp.v_sets.iter().map(|v| v.log_scale)),
    );
    let v_quats = ctx.storage_from("v set quats", &flat(inp.v_sets.iter().map(|v| v.quat)));
    let step = CocStep {
        view: VIEW,
        camera_centre: to_world(CAMERA).map(|v| v as f32),
        focus_scale: SCALE as f32,
        origin: ORIGIN.map(|v| v as f32),
        aperture: 1.0,
    };
    let mut ws = Workspace::default();
    let mut rec = ctx.recorder();
    let n = N as u32;
    let exp = kernels.encode_forward(
        &mut rec,
        &mut ws,
        &weights,
        &means,
        &log_scales,
        &quats,
        &focus,
        &apertures,
        n,
        &step,
    );
    let g = kernels.encode_backward(
        &mut rec,
        &mut ws,
        &weights,
        &quats,
        &exp,
        &v_means,
        &v_ls,
        &v_quats,
        VIEWS as u32,
        &step,
    );
    rec.submit();
    let sets = (config.copies as usize + 1) * N;
    let read = |b: &wgpu::Buffer, len: usize| ctx.read::<f32>(b, len).unwrap();
    let w = config.width as usize;
    let a = &exp.acts;
    // The GPU keeps γ(x_cam) once per step, beside the folded bias: each row is rebuilt whole.
    let camera = read(&a.camera, w + CAMERA_DIM);
    let rows = read(&a.input, N * ROW_DIM);
    let input = rows
        .chunks(ROW_DIM)
        .flat_map(|r| [&r[..MEAN_DIM], &camera[w..], &r[MEAN_DIM..]].concat())
        .collect();
    let acts = [
        input,
        read(&a.hidden[0], N * w),
        read(&a.hidden[1], N * w),
        read(&a.hidden[2], N * w),
        read(&a.heads, N * config.heads().len),
    ];
    Gpu {
        acts,
        sets: [
            read(&exp.means, 3 * sets),
            read(&exp.log_scales, 3 * sets),
            read(&exp.quats, 4 * sets),
        ],
        v_base: [
            read(&g.v_means, 3 * N),
            read(&g.v_log_scales, 3 * N),
            read(&g.v_quats, 4 * N),
        ],
        v_weights: read(&g.v_weights, config.mlp().len),
        v_focus: read(&g.v_focus, VIEWS),
        v_aperture: read(&g.v_aperture, VIEWS),
    }
}

fn gpu_trace(acts: &[Vec<f32>; 5], i: usize, config: &CocConfig) -> MlpTrace {
    let (w, h) = (config.width as usize, config.heads().len);
    let row = |l: usize, len: usize| -> Vec<f64> {
        acts[l][i * len..(i + 1) * len]
            .iter()
            .map(|&v| f64::from(v))
            .collect()
    };
    MlpTrace {
        layers: [
            row(0, ROW_DIM + CAMERA_DIM),
            row(1, w),
            row(2, w),
            row(3, w),
        ],
        heads: row(4, h),
    }
}

fn check(variant: CocVariant, centred: bool, modulate_base: bool, seed: u64) {
    let Some(ctx) = test_gpu() else { return };
    let config = CocConfig {
        centred,
        modulate_base,
        ..CocConfig::new(variant)
    };
    let inp = inputs(&config, seed);
    let gpu = run_gpu(ctx, config, &inp);
    let (hl, ml) = (config.heads(), config.mlp());
    let w64: Vec<f64> = inp.weights.iter().map(|&v| f64::from(v)).collect();
    let w_abs: Vec<f64> = w64.iter().map(|v| v.abs()).collect();
    let focus = f64::from(inp.focus[VIEW as usize]);
    let aperture = f64::from(APERTURES[VIEW as usize]);
    let sets = hl.copies + 1;

    let mut v_weights = vec![0.0; ml.len];
    // Σ|terms| of every weight gradient: the same backward on absolute values bounds it, which
    // gives each scalar an f32 rounding budget of its own.
    let mut v_weights_bound = vec![0.0; ml.len];
    let (mut v_focus, mut v_focus_bound) = (0.0, 0.0);
    let (mut v_aperture, mut v_aperture_bound) = (0.0, 0.0);
    let mut open = 0;
    for (i, base) in inp.bases.iter().enumerate() {
        let want = mlp_forward(&ml, &w64, input(base, CAMERA));
        // The GPU's own activations, checked here, drive the reference backward: an f32
        // pre-activation that lands on the other side of zero than in f64 flips a ReLU mask,
        // which is rounding, not a bug.
        let trace = gpu_trace(&gpu.acts, i, &config);
        for (l, (got, want)) in trace
            .layers
            .iter()
            .chain([&trace.heads])
            .zip(want.layers.iter().chain([&want.heads]))
            .enumerate()
        {
            for (k, (&g, &w)) in got.iter().zip(want).enumerate() {
                close(
                    &format!("{} layer {l} value {k} of Gaussian {i}", variant.name()),
                    g as f32,
                    w,
                    1e-4 * (1.0 + w.abs()),
                );
            }
        }
        let (c, dc) = variant_gate(variant, gate(base.mean, CAMERA, focus), SCALE);
        let depth = (0..3)
            .map(|k| (base.mean[k] - CAMERA[k]).powi(2))
            .sum::<f64>()
            .sqrt();
        let lens_k = aperture * depth;
        let expanded = expand(&config, base, &want.heads, (c, lens_k, SCALE));
        for (m, e) in expanded.iter().enumerate() {
            let o = m * inp.bases.len() + i;
            for (k, w) in to_world(e.mean).into_iter().enumerate() {
                close(
                    "set mean",
                    gpu.sets[0][3 * o + k],
                    w,
                    1e-5 * (1.0 + w.abs()),
                );
                let ls = e.log_scale[k] + SCALE.ln();
                close(
                    "set log-scale",
                    gpu.sets[1][3 * o + k],
                    ls,
                    1e-5 * (1.0 + ls.abs()),
                );
            }
            for k in 0..4 {
                close("set quat", gpu.sets[2][4 * o + k], e.quat[k], 1e-5);
            }
        }
        // The reference's sets are normalised: a world mean gradient is SCALE × theirs.
        let v: Vec<Expanded> = (0..sets)
            .map(|m| {
                let w = inp.v_sets[m * N + i];
                Expanded {
                    mean: w.mean.map(|g| g * SCALE),
                    ..w
                }
            })
            .collect();
        let g = expand_backward(&config, base, &trace.heads, (c, lens_k, SCALE), &v);
        open += g.v_heads.iter().filter(|v| **v != 0.0).count();
        for k in 0..3 {
            close(
                "v base mean",
                gpu.v_base[0][3 * i + k],
                g.base.mean[k] / SCALE,
                1e-5 * sets as f64,
            );
            close(
                "v base log-scale",
                gpu.v_base[1][3 * i + k],
                g.base.log_scale[k],
                1e-5 * sets as f64,
            );
        }
        for k in 0..4 {
            close(
                "v base quat",
                gpu.v_base[2][4 * i + k],
                g.base.quat[k],
                1e-4 * (1.0 + g.base.quat[k].abs()),
            );
        }
        // The focus buffer holds the normalised d_F, the reference's own parameter.
        v_focus += g.v_gate * dc;
        v_focus_bound += (g.v_gate * dc).abs();
        // K = a·d.
        v_aperture += g.v_lens_k * depth;
        v_aperture_bound += (g.v_lens_k * depth).abs();
        mlp_backward(&ml, &w64, &trace, &g.v_heads, &mut v_weights);
        let abs_trace = MlpTrace {
            layers: trace
                .layers
                .clone()
                .map(|l| l.iter().map(|v| v.abs()).collect()),
            heads: trace.heads.clone(),
        };
        let abs_heads: Vec<f64> = g.v_heads.iter().map(|v| v.abs()).collect();
        mlp_backward(&ml, &w_abs, &abs_trace, &abs_heads, &mut v_weights_bound);
    }
    assert!(
        open > N,
        "too few open multipliers ({open}) to test their gradients"
    );
    for p in 0..ml.len {
        let tol = 1e-7 + 2e-5 * v_weights_bound[p];
        close(
            &format!("{} v weight {p}", variant.name()),
            gpu.v_weights[p],
            v_weights[p],
            tol,
        );
    }
    close(
        "v focus",
        gpu.v_focus[VIEW as usize],
        v_focus,
        1e-6 + 2e-5 * v_focus_bound,
    );
    assert!(
        v_focus.abs() > 1e-3 * v_focus_bound,
        "focus gradient must not cancel out"
    );
    close(
        "v aperture",
        gpu.v_aperture[VIEW as usize],
        v_aperture,
        1e-6 + 2e-5 * v_aperture_bound,
    );
    if variant == CocVariant::Lens {
        assert!(
            v_aperture.abs() > 1e-3 * v_aperture_bound,
            "aperture gradient must not cancel out"
        );
    }
    for (view, v) in gpu.v_focus.iter().enumerate() {
        if view != VIEW as usize {
            assert_eq!(*v, 0.0, "only the step's view gets a focus gradient");
        }
    }
}

#[test]
fn code_variant_matches_the_reference() {
    check(CocVariant::Code, false, true, 3);
    check(CocVariant::Code, true, false, 13);
}

#[test]
fn paper_variant_matches_the_reference() {
    check(CocVariant::Paper, false, true, 4);
    check(CocVariant::Paper, true, false, 14);
}

#[test]
fn lens_variant_matches_the_reference() {
    check(CocVariant::Lens, false, false, 5);
    check(CocVariant::Lens, true, true, 15);
}

/// Opacity and SH gradients of the sets sum into their base.
#[test]
fn per_set_gradients_sum_into_the_base() {
    let Some(ctx) = test_gpu() else { return };
    let config = CocConfig::new(CocVariant::Code);
    let kernels = CocKernels::new(ctx, config);
    let len = 300u32;
    let sets = config.copies + 1;
    let src: Vec<f32> = (0..len * sets)
        .map(|i| ((i * 37) % 101) as f32 * 0.01 - 0.5)
        .collect();
    let a = ctx.storage_from("src", &src);
    let b = ctx.storage("dst", u64::from(len) * 4);
    let mut rec = ctx.recorder();
    kernels.encode_sum_sets(&mut rec, &a, &b, len);
    rec.submit();
    let got: Vec<f32> = ctx.read(&b, len as usize).unwrap();
    for j in 0..len as usize {
        let want: f32 = (0..sets as usize).map(|m| src[m * len as usize + j]).sum();
        assert!((got[j] - want).abs() < 1e-5, "{j}: {} vs {want}", got[j]);
    }
}
