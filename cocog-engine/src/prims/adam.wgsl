// Adam update of one flat f32 parameter buffer, with bias correction folded into the step
// (the same arithmetic as torch.optim.Adam, which 3DGS and CoCoGaussian use). One buffer can
// hold two torch parameter groups interleaved: every `period`-th element (from 0) steps at
// `lr`, the others at `lr_rest`. The SH buffer needs this: INRIA trains f_dc and f_rest as
// groups with different rates, and the engine stores them per Gaussian and channel together.

struct Params {
    n: u32,
    lr: f32,
    beta1: f32,
    beta2: f32,
    eps: f32,
    // 1 − β₁ᵗ and 1 − β₂ᵗ
    bias1: f32,
    bias2: f32,
    period: u32,
    lr_rest: f32,
    pad0: u32,
    pad1: u32,
    pad2: u32,
}

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read_write> param: array<f32>;
@group(0) @binding(2) var<storage, read> grad: array<f32>;
@group(0) @binding(3) var<storage, read_write> m1: array<f32>;
@group(0) @binding(4) var<storage, read_write> m2: array<f32>;
// A step whose inputs were unusable (the renderer's intersection buffer overflowed) is
// skipped on the GPU: skip[0] != 0 leaves parameters and moments untouched.
@group(0) @binding(5) var<storage, read> skip: array<u32>;

@compute @workgroup_size(256)
fn adam(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = gid.x + gid.y * nwg.x * 256u;
    if (i >= params.n || skip[0] != 0u) {
        return;
    }
    let lr = select(params.lr_rest, params.lr, i % params.period == 0u);
    let g = grad[i];
    let m = params.beta1 * m1[i] + (1.0 - params.beta1) * g;
    let v = params.beta2 * m2[i] + (1.0 - params.beta2) * g * g;
    m1[i] = m;
    m2[i] = v;
    param[i] -= lr / params.bias1 * m / (sqrt(v / params.bias2) + params.eps);
}
