//! f64 CPU reference of h_θ and the CoC expansion, the oracle of the GPU kernels and what the
//! finite-difference tests differentiate.
//!
//! Everything here is in the scene's normalised frame (positions and lengths divided by the
//! scene scale D, from an origin), as the GPU computes it: h_θ then sees the same numbers in
//! any unit, and the gate |1/d − 1/d_F| is dimensionless. The GPU maps offsets back by × D.
//! The code variant alone works in the scene's own units, as the released code does
//! (`variant_gate`, and `expand`'s `scale`).

// Index loops mirror the formulas of method.md §3–§4.
#![allow(clippy::needless_range_loop)]

use super::layout::{
    CAMERA_FREQS, CocConfig, CocVariant, HeadLayout, INPUT_DIM, MEAN_FREQS, MlpLayout,
};

/// Upper end of the scale and rotation multipliers (method.md §3.4: δ_max = 1.1).
pub const DELTA_MAX: f64 = 1.1;
/// Below this gated head value the multiplier is exactly 1 (the released code's `e − 0.01`).
pub const DELTA_OFFSET: f64 = 0.01;

/// One base Gaussian as h_θ and the expansion see it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Base {
    pub mean: [f64; 3],
    pub log_scale: [f64; 3],
    /// The raw (unnormalised) rotation parameter.
    pub quat: [f64; 4],
}

/// One expanded Gaussian (a CoC copy or the modulated base set).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Expanded {
    pub mean: [f64; 3],
    pub log_scale: [f64; 3],
    pub quat: [f64; 4],
}

/// NeRF's embedder without π: x, then sin and cos of 2^k·x for k < freqs.
fn embed(x: [f64; 3], freqs: usize, out: &mut Vec<f64>) {
    out.extend(x);
    for k in 0..freqs {
        let f = f64::from(1u32 << k);
        out.extend(x.map(|v| (f * v).sin()));
        out.extend(x.map(|v| (f * v).cos()));
    }
}

fn normalize4(q: [f64; 4]) -> ([f64; 4], f64) {
    let n = q.iter().map(|v| v * v).sum::<f64>().sqrt();
    (q.map(|v| v / n), n)
}

/// The 91-d input of h_θ: [γ(μ), γ(x_cam), exp(log-scale), q/|q|] (all detached).
pub fn input(base: &Base, camera_centre: [f64; 3]) -> Vec<f64> {
    let mut x = Vec::with_capacity(INPUT_DIM);
    embed(base.mean, MEAN_FREQS, &mut x);
    embed(camera_centre, CAMERA_FREQS, &mut x);
    x.extend(base.log_scale.map(f64::exp));
    x.extend(normalize4(base.quat).0);
    x
}

/// Activations of one forward pass: the input, the three ReLU layers, the heads.
#[derive(Clone, Debug, PartialEq)]
pub struct MlpTrace {
    pub layers: [Vec<f64>; 4],
    pub heads: Vec<f64>,
}

fn linear(w: &[f64], l: (usize, usize, usize, usize), x: &[f64], relu: bool) -> Vec<f64> {
    let (fan_in, fan_out, wo, bo) = l;
    (0..fan_out)
        .map(|j| {
            let row = &w[wo + j * fan_in..wo + (j + 1) * fan_in];
            let s = w[bo + j] + row.iter().zip(x).map(|(a, b)| a * b).sum::<f64>();
            if relu { s.max(0.0) } else { s }
        })
        .collect()
}

pub fn mlp_forward(layout: &MlpLayout, weights: &[f64], x: Vec<f64>) -> MlpTrace {
    let l = layout.layers;
    let a1 = linear(weights, l[0], &x, true);
    let a2 = linear(weights, l[1], &a1, true);
    let a3 = linear(weights, l[2], &a2, true);
    let heads = linear(weights, l[3], &a3, false);
    MlpTrace {
        layers: [x, a1, a2, a3],
        heads,
    }
}

/// Adds the weight gradients of one Gaussian's pass, given the gradient of its heads, into
/// `v_weights` (the input is detached: nothing flows further).
pub fn mlp_backward(
    layout: &MlpLayout,
    weights: &[f64],
    t: &MlpTrace,
    v_heads: &[f64],
    v_weights: &mut [f64],
) {
    let mut delta = v_heads.to_vec();
    for layer in (0..4).rev() {
        let (fan_in, fan_out, wo, bo) = layout.layers[layer];
        let a = &t.layers[layer];
        let mut v_a = vec![0.0; fan_in];
        for j in 0..fan_out {
            v_weights[bo + j] += delta[j];
            for i in 0..fan_in {
                v_weights[wo + j * fan_in + i] += delta[j] * a[i];
                v_a[i] += delta[j] * weights[wo + j * fan_in + i];
            }
        }
        if layer > 0 {
            // ReLU: the stored activation is zero exactly where the pre-activation was ≤ 0.
            delta = v_a
                .iter()
                .zip(a)
                .map(|(g, &v)| if v > 0.0 { *g } else { 0.0 })
                .collect();
        }
    }
}

/// The CoC gate |1/d − 1/d_F| with d the (detached) distance from the camera centre, and its
/// derivative with respect to d_F.
pub fn gate(mean: [f64; 3], camera_centre: [f64; 3], focus: f64) -> (f64, f64) {
    let d = (0..3)
        .map(|k| (mean[k] - camera_centre[k]).powi(2))
        .sum::<f64>()
        .sqrt();
    let diff = 1.0 / d - 1.0 / focus;
    (diff.abs(), diff.signum() / (focus * focus))
}

/// `gate`'s values as `variant` uses them, for a frame of scale D: the code variant's gate is
/// the released code's |1/d − 1/d_F| in the scene's units, the frame's ÷ D.
pub fn variant_gate(variant: CocVariant, gate: (f64, f64), scale: f64) -> (f64, f64) {
    match variant {
        CocVariant::Code => (gate.0 / scale, gate.1 / scale),
        CocVariant::Paper | CocVariant::Lens => gate,
    }
}

/// The multiplier δ = log(clamp(x, e, e^1.1)) ∈ [1, 1.1] of x = c·h + e − 0.01, and 1/x
/// where unclamped (0 where clamped): ∂δ/∂h = c/x, ∂δ/∂c = h/x.
pub fn multiplier(c: f64, h: f64) -> (f64, f64) {
    let e = std::f64::consts::E;
    let x = c * h + e - DELTA_OFFSET;
    if x <= e {
        (1.0, 0.0)
    } else if x >= DELTA_MAX.exp() {
        (DELTA_MAX, 0.0)
    } else {
        (x.ln(), 1.0 / x)
    }
}

fn softplus(x: f64) -> f64 {
    if x > 20.0 { x } else { x.exp().ln_1p() }
}

fn sigmoid(x: f64) -> f64 {
    1.0 / (1.0 + (-x).exp())
}

/// The aperture K of the paper's and the lens variant's circle of confusion K·c: the paper's
/// head, or for the lens variant the photo's aperture a times the Gaussian's depth d (so that
/// K·c/2 = a/2·|1 − d/d_F|, the thin lens's radius).
fn aperture_k(variant: CocVariant, hl: &HeadLayout, heads: &[f64], lens_k: f64) -> f64 {
    match variant {
        CocVariant::Paper => softplus(heads[hl.aperture.unwrap_or(0)]),
        _ => lens_k,
    }
}

/// The offset of copy m < M, given the heads and the gate; `lens_k` is the lens variant's K,
/// `scale` the frame's D (the code variant's offset c·raw is in scene units).
fn offset(
    variant: CocVariant,
    hl: &HeadLayout,
    heads: &[f64],
    (c, lens_k, scale): (f64, f64, f64),
    m: usize,
) -> [f64; 3] {
    let raw = [0, 1, 2].map(|k| heads[hl.pos + 3 * m + k]);
    match variant {
        CocVariant::Code => raw.map(|v| c * v / scale),
        CocVariant::Paper | CocVariant::Lens => {
            let k = aperture_k(variant, hl, heads, lens_k);
            let beta = sigmoid(heads[hl.beta.unwrap_or(0) + m]);
            let n = raw.iter().map(|v| v * v).sum::<f64>().sqrt().max(1e-12);
            raw.map(|v| 0.5 * k * c * beta * v / n)
        }
    }
}

/// The M copies' offsets; with `centred`, their mean is subtracted, so the copies sit
/// around the base like a circle of confusion around its in-focus point.
fn offsets(
    variant: CocVariant,
    hl: &HeadLayout,
    heads: &[f64],
    gate: (f64, f64, f64),
    centred: bool,
) -> Vec<[f64; 3]> {
    let mut out: Vec<[f64; 3]> = (0..hl.copies)
        .map(|m| offset(variant, hl, heads, gate, m))
        .collect();
    if centred && !out.is_empty() {
        let mean = [0, 1, 2].map(|k| out.iter().map(|o| o[k]).sum::<f64>() / out.len() as f64);
        for o in &mut out {
            for k in 0..3 {
                o[k] -= mean[k];
            }
        }
    }
    out
}

/// The gate of set m's scale and rotation multipliers: closed for the base set unless the
/// configuration modulates it.
fn modulation_gate(config: &CocConfig, m: usize, c: f64) -> f64 {
    if m == config.copies as usize && !config.modulate_base {
        0.0
    } else {
        c
    }
}

/// The M + 1 sets of one base Gaussian, copies first and the (modulated) base set last;
/// `c` is `variant_gate`'s, `lens_k` the lens variant's K = a·d (ignored by the others),
/// `scale` the frame's D.
pub fn expand(
    config: &CocConfig,
    base: &Base,
    heads: &[f64],
    (c, lens_k, scale): (f64, f64, f64),
) -> Vec<Expanded> {
    let (variant, hl) = (config.variant, &config.heads());
    let (unit, _) = normalize4(base.quat);
    let shifts = offsets(variant, hl, heads, (c, lens_k, scale), config.centred);
    (0..=hl.copies)
        .map(|m| {
            let shift = shifts.get(m).copied().unwrap_or([0.0; 3]);
            let c = modulation_gate(config, m, c);
            Expanded {
                mean: [0, 1, 2].map(|k| base.mean[k] + shift[k]),
                log_scale: [0, 1, 2]
                    .map(|k| base.log_scale[k] + multiplier(c, heads[hl.scale + 3 * m + k]).0.ln()),
                quat: [0, 1, 2, 3].map(|k| unit[k] * multiplier(c, heads[hl.rot + 4 * m + k]).0),
            }
        })
        .collect()
}

/// Gradients the adjoint of `expand` produces for one base Gaussian.
#[derive(Clone, Debug, PartialEq)]
pub struct ExpandGrads {
    pub base: Expanded,
    pub v_heads: Vec<f64>,
    /// d loss / d c (the gate); times `gate`'s second value it is this Gaussian's share of
    /// the focus distance's gradient.
    pub v_gate: f64,
    /// d loss / d K of the lens variant (times d, this Gaussian's share of the aperture's).
    pub v_lens_k: f64,
}

/// The adjoint of `expand`: `v` holds the gradient of every set (same order).
pub fn expand_backward(
    config: &CocConfig,
    base: &Base,
    heads: &[f64],
    (c, lens_k, scale): (f64, f64, f64),
    v: &[Expanded],
) -> ExpandGrads {
    let (variant, centred, hl) = (config.variant, config.centred, &config.heads());
    let mut v_lens_k = 0.0;
    let (unit, norm) = normalize4(base.quat);
    // Centring subtracts the mean offset: each copy's offset gradient loses the copies' mean.
    let m_copies = hl.copies.max(1) as f64;
    let g_mean = [0, 1, 2].map(|k| {
        if centred {
            v[..hl.copies].iter().map(|g| g.mean[k]).sum::<f64>() / m_copies
        } else {
            0.0
        }
    });
    let mut v_heads = vec![0.0; hl.len];
    let mut v_gate = 0.0;
    let mut v_mean = [0.0; 3];
    let mut v_log_scale = [0.0; 3];
    let mut v_unit = [0.0; 4];
    for m in 0..=hl.copies {
        let g = &v[m];
        let cm = modulation_gate(config, m, c);
        for k in 0..3 {
            v_mean[k] += g.mean[k];
            v_log_scale[k] += g.log_scale[k];
            // log_scale' = log_scale + ln δ.
            let h = heads[hl.scale + 3 * m + k];
            let (d, inv) = multiplier(cm, h);
            v_heads[hl.scale + 3 * m + k] += g.log_scale[k] * cm * inv / d;
            v_gate += g.log_scale[k] * h * inv / d;
        }
        for k in 0..4 {
            let h = heads[hl.rot + 4 * m + k];
            let (d, inv) = multiplier(cm, h);
            v_unit[k] += g.quat[k] * d;
            v_heads[hl.rot + 4 * m + k] += g.quat[k] * unit[k] * cm * inv;
            v_gate += g.quat[k] * unit[k] * h * inv;
        }
        if m == hl.copies {
            continue;
        }
        let raw = [0, 1, 2].map(|k| heads[hl.pos + 3 * m + k]);
        let g_off = [0, 1, 2].map(|k| g.mean[k] - g_mean[k]);
        match variant {
            CocVariant::Code => {
                for k in 0..3 {
                    v_heads[hl.pos + 3 * m + k] += c * g_off[k] / scale;
                    v_gate += raw[k] * g_off[k] / scale;
                }
            }
            CocVariant::Paper | CocVariant::Lens => {
                let kb = hl.beta.unwrap_or(0) + m;
                let (aperture, beta) = (aperture_k(variant, hl, heads, lens_k), sigmoid(heads[kb]));
                let n = raw.iter().map(|v| v * v).sum::<f64>().sqrt().max(1e-12);
                let dir = raw.map(|v| v / n);
                let dot: f64 = (0..3).map(|k| dir[k] * g_off[k]).sum();
                // shift = ½·K·c·β·dir.
                let v_k = 0.5 * c * beta * dot;
                match hl.aperture {
                    Some(ka) => v_heads[ka] += v_k * sigmoid(heads[ka]),
                    None => v_lens_k += v_k,
                }
                v_heads[kb] += 0.5 * aperture * c * dot * beta * (1.0 - beta);
                v_gate += 0.5 * aperture * beta * dot;
                let s = 0.5 * aperture * c * beta;
                for k in 0..3 {
                    v_heads[hl.pos + 3 * m + k] += s * (g_off[k] - dir[k] * dot) / n;
                }
            }
        }
    }
    let dot: f64 = (0..4).map(|k| unit[k] * v_unit[k]).sum();
    ExpandGrads {
        base: Expanded {
            mean: v_mean,
            log_scale: v_log_scale,
            quat: [0, 1, 2, 3].map(|k| (v_unit[k] - unit[k] * dot) / norm),
        },
        v_heads,
        v_gate,
        v_lens_k,
    }
}
