// ∂loss/∂focus[view] and ∂loss/∂aperture[view] (lens variant): the Gaussians' terms summed by
// one workgroup in a fixed order, so a step's gradient is reproducible.

@group(0) @binding(0) var<uniform> step: Step;
@group(0) @binding(1) var<storage, read> focus_terms: array<vec2<f32>>;
@group(0) @binding(2) var<storage, read_write> v_focus: array<f32>;
@group(0) @binding(3) var<storage, read_write> v_aperture: array<f32>;

var<workgroup> sums: array<vec2<f32>, 256>;

@compute @workgroup_size(256)
fn focus_sum(@builtin(local_invocation_index) lid: u32) {
    var s = vec2<f32>(0.0);
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
        v_focus[step.view] = sums[0].x;
        v_aperture[step.view] = sums[0].y;
    }
}
