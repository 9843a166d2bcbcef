// Shared by every CoC kernel; the Rust side prepends the shape constants (M, WIDTH, HEADS, the
// head offsets H_*, the layer table L*_*, MAXD, ACT_STRIDE, DELTA_STRIDE, P_TOTAL, CHUNK).

struct Step {
    n: u32,
    view: u32,
    // d_F = focus[view] · focus_scale (the released code learns focus / max depth).
    focus_scale: f32,
    chunks: u32,
    centre: vec3<f32>,
    pad: u32,
}

const E: f32 = 2.718281828459045;
const DELTA_MAX: f32 = 1.1;
const DELTA_OFFSET: f32 = 0.01;

// δ = log(clamp(c·h + e − 0.01, e, e^1.1)) ∈ [1, 1.1], and 1/x where unclamped (0 where clamped).
fn multiplier(c: f32, h: f32) -> vec2<f32> {
    let x = c * h + E - DELTA_OFFSET;
    if x <= E {
        return vec2<f32>(1.0, 0.0);
    }
    if x >= exp(DELTA_MAX) {
        return vec2<f32>(DELTA_MAX, 0.0);
    }
    return vec2<f32>(log(x), 1.0 / x);
}

fn softplus(x: f32) -> f32 {
    if x > 20.0 {
        return x;
    }
    return log(1.0 + exp(x));
}

fn sigmoid(x: f32) -> f32 {
    return 1.0 / (1.0 + exp(-x));
}

// (fan in, fan out, weight offset, bias offset) of layer l (0–2 the trunk, 3 the heads).
fn layer_dims(l: u32) -> vec4<u32> {
    switch l {
        case 0u: { return vec4<u32>(L0_IN, L0_OUT, L0_W, L0_B); }
        case 1u: { return vec4<u32>(L1_IN, L1_OUT, L1_W, L1_B); }
        case 2u: { return vec4<u32>(L2_IN, L2_OUT, L2_W, L2_B); }
        default: { return vec4<u32>(L3_IN, L3_OUT, L3_W, L3_B); }
    }
}

// Where layer l's input sits in a Gaussian's row of `acts` ([input | a1 | a2 | a3 | heads]).
fn act_offset(l: u32) -> u32 {
    if l == 0u {
        return 0u;
    }
    return IN_DIM + (l - 1u) * WIDTH;
}

// Linear index of a 1D dispatch folded into a 2D grid (Kernel::dispatch_1d).
fn linear_id(wg: vec3<u32>, nwg: vec3<u32>, lid: u32, size: u32) -> u32 {
    return (wg.y * nwg.x + wg.x) * size + lid;
}
