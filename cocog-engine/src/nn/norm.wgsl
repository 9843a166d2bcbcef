// ReLU then InstanceNorm (no affine, biased variance, ε 1e-5) over each (image, channel) plane
// of [image][channel][y][x] maps, and its adjoint. The pre-activation and normalised output
// are stored as map_t (the prelude's: f16 or f32); statistics and gradients are f32. The
// statistics kernels run one workgroup per plane; the element kernels take PER_INVOCATION
// values per invocation (composite.rs prepends it).

struct Norm {
    planes: u32,
    // Values per plane (height × width).
    size: u32,
    eps: f32,
    pad: u32,
}

@group(0) @binding(0) var<uniform> nm: Norm;
// Pre-activation (the convolution's output).
@group(0) @binding(1) var<storage, read> z: array<map_t>;
// Normalised output.
@group(0) @binding(2) var<storage, read_write> y: array<map_t>;
// Per plane: mean, 1/σ.
@group(0) @binding(3) var<storage, read_write> stats: array<f32>;
@group(0) @binding(4) var<storage, read> v_y: array<f32>;
@group(0) @binding(5) var<storage, read_write> v_z: array<f32>;
// Per plane: mean(v_y), mean(v_y · y).
@group(0) @binding(6) var<storage, read_write> grad_stats: array<f32>;

var<workgroup> sums: array<vec2<f32>, 256>;

fn reduce(lid: u32, v: vec2<f32>) -> vec2<f32> {
    sums[lid] = v;
    for (var w = 128u; w > 0u; w >>= 1u) {
        workgroupBarrier();
        if lid < w {
            sums[lid] += sums[lid + w];
        }
    }
    workgroupBarrier();
    let total = sums[0];
    workgroupBarrier();
    return total;
}

fn plane_of(wg: vec3<u32>, nwg: vec3<u32>) -> u32 {
    return wg.y * nwg.x + wg.x;
}

// The sum over a plane of ReLU(z) − shift, or of its square, with four independent loads in
// flight per invocation: one at a time, the statistics ran at 240 GB/s on an H200, bound by
// the loads' latency.
fn plane_sum(lid: u32, base: u32, shift: f32, squared: bool) -> f32 {
    var s = 0.0;
    var j = lid;
    for (; j + 768u < nm.size; j += 1024u) {
        let v = max(vec4<f32>(f32(z[base + j]), f32(z[base + j + 256u]),
            f32(z[base + j + 512u]), f32(z[base + j + 768u])), vec4<f32>(0.0)) - shift;
        s += select(dot(v, vec4<f32>(1.0)), dot(v, v), squared);
    }
    for (; j < nm.size; j += 256u) {
        let v = max(f32(z[base + j]), 0.0) - shift;
        s += select(v, v * v, squared);
    }
    return reduce(lid, vec2<f32>(s, 0.0)).x;
}

// Two passes, the mean and then the variance about it: one pass's E[x²] − E[x]² cancels on
// nearly flat planes (the f64 reference tests catch it).
@compute @workgroup_size(256)
fn norm_stats(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let plane = plane_of(wg, nwg);
    if plane >= nm.planes {
        return;
    }
    let base = plane * nm.size;
    let mean = plane_sum(lid, base, 0.0, false) / f32(nm.size);
    let var_ = plane_sum(lid, base, mean, true) / f32(nm.size);
    if lid == 0u {
        stats[2u * plane] = mean;
        stats[2u * plane + 1u] = inverseSqrt(var_ + nm.eps);
    }
}

// The element kernels take PER_INVOCATION values per invocation, 256 apart so each load is
// coalesced across a subgroup: at one value each, norm_apply moved 1.2 TB/s on an H200.

fn first_element(wg: vec3<u32>, nwg: vec3<u32>, lid: u32) -> u32 {
    return (wg.y * nwg.x + wg.x) * 256u * PER_INVOCATION + lid;
}

@compute @workgroup_size(256)
fn norm_apply(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let first = first_element(wg, nwg, lid);
    for (var k = 0u; k < PER_INVOCATION; k++) {
        let t = first + 256u * k;
        if t >= nm.planes * nm.size {
            return;
        }
        let plane = t / nm.size;
        y[t] = to_map((max(f32(z[t]), 0.0) - stats[2u * plane]) * stats[2u * plane + 1u]);
    }
}

@compute @workgroup_size(256)
fn norm_grad_stats(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let plane = plane_of(wg, nwg);
    if plane >= nm.planes {
        return;
    }
    let base = plane * nm.size;
    // Four independent loads of each map in flight per invocation, as in plane_sum.
    var s = vec2<f32>(0.0);
    var j = lid;
    for (; j + 768u < nm.size; j += 1024u) {
        let g = vec4<f32>(v_y[base + j], v_y[base + j + 256u], v_y[base + j + 512u],
            v_y[base + j + 768u]);
        let v = vec4<f32>(f32(y[base + j]), f32(y[base + j + 256u]), f32(y[base + j + 512u]),
            f32(y[base + j + 768u]));
        s += vec2<f32>(dot(g, vec4<f32>(1.0)), dot(g, v));
    }
    for (; j < nm.size; j += 256u) {
        let g = v_y[base + j];
        s += vec2<f32>(g, g * f32(y[base + j]));
    }
    let total = reduce(lid, s) / f32(nm.size);
    if lid == 0u {
        grad_stats[2u * plane] = total.x;
        grad_stats[2u * plane + 1u] = total.y;
    }
}

// ∂/∂z = [z > 0] · (1/σ) · (v_y − mean(v_y) − y · mean(v_y · y)).
@compute @workgroup_size(256)
fn norm_backward(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let first = first_element(wg, nwg, lid);
    for (var k = 0u; k < PER_INVOCATION; k++) {
        let t = first + 256u * k;
        if t >= nm.planes * nm.size {
            return;
        }
        let plane = t / nm.size;
        var g = 0.0;
        if f32(z[t]) > 0.0 {
            g = stats[2u * plane + 1u] * (v_y[t] - grad_stats[2u * plane] - f32(y[t]) * grad_stats[2u * plane + 1u]);
        }
        v_z[t] = g;
    }
}
