// INRIA add_densification_stats: for every Gaussian visible in this view (radius > 0), add the
// norm of its screen-space mean gradient to `accum` and count the view in `denom`. The engine's
// gradient is per pixel; INRIA's is per NDC unit (pixel = ((ndc + 1)·size − 1) / 2), so each
// component is scaled by size / 2 to keep the 0.0002 threshold meaningful.
// With CoC sets (method.md §7) the pass rendered `sets` copies of every Gaussian, [set][base]:
// each visible copy adds its norm and 1/sets of a view, as the released code does.

struct Params {
    n: u32,
    half_width: f32,
    half_height: f32,
    sets: u32,
}

@group(0) @binding(0) var<uniform> params: Params;
// 12 floats per Gaussian; [7] is the radius in pixels, 0 when culled.
@group(0) @binding(1) var<storage, read> projected: array<f32>;
// 10 floats per Gaussian; [0], [1] are ∂loss/∂mean2d.
@group(0) @binding(2) var<storage, read> v_projected: array<f32>;
@group(0) @binding(3) var<storage, read_write> accum: array<f32>;
@group(0) @binding(4) var<storage, read_write> denom: array<f32>;
// The renderer's status: [0] != 0 when its intersection buffers overflowed (a skipped step).
@group(0) @binding(5) var<storage, read> status: array<u32>;

@compute @workgroup_size(256)
fn accumulate(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = gid.x + gid.y * nwg.x * 256u;
    if (i >= params.n || status[0] != 0u) {
        return;
    }
    for (var m = 0u; m < params.sets; m++) {
        let j = m * params.n + i;
        if (projected[12u * j + 7u] > 0.0) {
            let g = vec2<f32>(v_projected[10u * j] * params.half_width, v_projected[10u * j + 1u] * params.half_height);
            accum[i] += length(g);
            denom[i] += 1.0 / f32(params.sets);
        }
    }
}
