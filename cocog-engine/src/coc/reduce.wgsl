// ∂loss/∂focus[view] and ∂loss/∂aperture[view] (lens variant): the Gaussians' terms summed by
// one workgroup in a fixed order, so a step's gradient is reproducible.

@group(0) @binding(0) var<uniform> step: Step;
@group(0) @binding(1) var<storage, read> focus_terms: array<vec2<f32>>;
@group(0) @binding(2) var<storage, read_write> v_focus: array<f32>;
@group(0) @binding(3) var<storage, read_write> v_aperture: array<f32>;

var<workgroup> sums: array<vec2<f32>, 256>;

@compute @workgroup_size(256)
fn focus_sum(@builtin(local_invocation_index) lid: u32) {
    // Four running sums, so four loads are in flight (one chain of 230 loads per invocation
    // took 0.1 ms for 58k Gaussians on an H200).
    var s0 = vec2<f32>(0.0);
    var s1 = vec2<f32>(0.0);
    var s2 = vec2<f32>(0.0);
    var s3 = vec2<f32>(0.0);
    var n = lid;
    for (; n + 768u < step.n; n += 1024u) {
        s0 += focus_terms[n];
        s1 += focus_terms[n + 256u];
        s2 += focus_terms[n + 512u];
        s3 += focus_terms[n + 768u];
    }
    for (; n < step.n; n += 256u) {
        s0 += focus_terms[n];
    }
    sums[lid] = (s0 + s1) + (s2 + s3);
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
