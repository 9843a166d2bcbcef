// Adam on the SH buffer with two learning rates: INRIA optimises f_dc and f_rest as separate
// groups (rest at lr / 20), but the engine stores them interleaved per Gaussian and channel
// (sh[g][c][k], k = 0 the DC term), so the rate is chosen per element. Same arithmetic as the
// engine's adam.wgsl otherwise.

struct Params {
    n: u32,
    // SH coefficients per channel: k = i % coeffs.
    coeffs: u32,
    lr_dc: f32,
    lr_rest: f32,
    beta1: f32,
    beta2: f32,
    eps: f32,
    // 1 − β₁ᵗ and 1 − β₂ᵗ
    bias1: f32,
    bias2: f32,
    // Scalars, not an array: uniform arrays need a 16-byte element stride.
    pad0: u32,
    pad1: u32,
    pad2: u32,
}

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read_write> param: array<f32>;
@group(0) @binding(2) var<storage, read> grad: array<f32>;
@group(0) @binding(3) var<storage, read_write> m1: array<f32>;
@group(0) @binding(4) var<storage, read_write> m2: array<f32>;

@compute @workgroup_size(256)
fn sh_adam(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = gid.x + gid.y * nwg.x * 256u;
    if (i >= params.n) {
        return;
    }
    let lr = select(params.lr_rest, params.lr_dc, i % params.coeffs == 0u);
    let g = grad[i];
    let m = params.beta1 * m1[i] + (1.0 - params.beta1) * g;
    let v = params.beta2 * m2[i] + (1.0 - params.beta2) * g * g;
    m1[i] = m;
    m2[i] = v;
    param[i] -= lr / params.bias1 * m / (sqrt(v / params.bias2) + params.eps);
}
