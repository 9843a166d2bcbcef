// Shared by the per-Gaussian CoC kernels; the Rust side prepends the shape constants (M, WIDTH,
// HEADS, the head offsets H_*, IN_DIM and the encoding frequencies).

struct Step {
    n: u32,
    view: u32,
    // The scene scale D: h_θ sees lengths divided by it and positions measured from `origin`,
    // so the same numbers in any unit; focus[view] is d_F / D and world offsets are D × the
    // normalised ones.
    scale: f32,
    // Multiplies the gate: 1 as photographed, 0 a pinhole (refocused renders choose it).
    aperture: f32,
    centre: vec3<f32>,
    pad0: u32,
    origin: vec3<f32>,
    pad1: u32,
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

// Linear index of a 1D dispatch folded into a 2D grid (Kernel::dispatch_1d).
fn linear_id(wg: vec3<u32>, nwg: vec3<u32>, lid: u32, size: u32) -> u32 {
    return (wg.y * nwg.x + wg.x) * size + lid;
}
