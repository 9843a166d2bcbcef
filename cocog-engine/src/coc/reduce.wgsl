// Reductions over Gaussians, in a fixed order so a step's gradients are reproducible:
// h_θ's weight gradients (per-chunk partial sums, then their sum) and the focus distance's
// gradient.

@group(0) @binding(0) var<uniform> step: Step;
@group(0) @binding(1) var<storage, read> acts: array<f32>;
@group(0) @binding(2) var<storage, read> deltas: array<f32>;
@group(0) @binding(3) var<storage, read_write> partials: array<f32>;
@group(0) @binding(4) var<storage, read_write> v_weights: array<f32>;
@group(0) @binding(5) var<storage, read> focus_terms: array<f32>;
@group(0) @binding(6) var<storage, read_write> v_focus: array<f32>;

// One thread per (parameter, chunk of CHUNK Gaussians): Σ δ[j]·a[i] (a = 1 for a bias).
@compute @workgroup_size(256)
fn weight_partials(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let p = wg.x * 256u + lid;
    let chunk = wg.y;
    if p >= P_TOTAL {
        return;
    }
    var l = 0u;
    var d = layer_dims(0u);
    for (; l < 3u; l++) {
        d = layer_dims(l);
        if p < d.w + d.y {
            break;
        }
    }
    d = layer_dims(l);
    var j: u32;
    var i = 0u;
    let bias = p >= d.w;
    if bias {
        j = p - d.w;
    } else {
        j = (p - d.z) / d.x;
        i = (p - d.z) % d.x;
    }
    let a_at = act_offset(l) + i;
    let d_at = l * WIDTH + j;
    let end = min(step.n, (chunk + 1u) * CHUNK);
    var s = 0.0;
    for (var n = chunk * CHUNK; n < end; n++) {
        var a = 1.0;
        if !bias {
            a = acts[n * ACT_STRIDE + a_at];
        }
        s += deltas[n * DELTA_STRIDE + d_at] * a;
    }
    partials[chunk * P_TOTAL + p] = s;
}

@compute @workgroup_size(256)
fn weight_sum(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let p = wg.x * 256u + lid;
    if p >= P_TOTAL {
        return;
    }
    var s = 0.0;
    for (var c = 0u; c < step.chunks; c++) {
        s += partials[c * P_TOTAL + p];
    }
    v_weights[p] = s;
}

var<workgroup> sums: array<f32, 256>;

// One workgroup: ∂loss/∂focus[view] = Σ over Gaussians of their terms.
@compute @workgroup_size(256)
fn focus_sum(@builtin(local_invocation_index) lid: u32) {
    var s = 0.0;
    for (var n = lid; n < step.n; n += 256u) {
        s += focus_terms[n];
    }
    sums[lid] = s;
    for (var w = 128u; w > 0u; w >>= 1u) {
        workgroupBarrier();
        if lid < w {
            sums[lid] += sums[lid + w];
        }
    }
    if lid == 0u {
        v_focus[step.view] = sums[0];
    }
}
