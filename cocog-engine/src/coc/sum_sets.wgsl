// dst[j] = Σ over the M + 1 sets of src[set·len + j]: the base's share of a per-set gradient
// (opacity, SH), which the copies take unchanged from their base.

struct Sizes {
    len: u32,
    sets: u32,
    pad0: u32,
    pad1: u32,
}

@group(0) @binding(0) var<uniform> sizes: Sizes;
@group(0) @binding(1) var<storage, read> src: array<f32>;
@group(0) @binding(2) var<storage, read_write> dst: array<f32>;

@compute @workgroup_size(256)
fn sum_sets(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let j = (wg.y * nwg.x + wg.x) * 256u + lid;
    if j >= sizes.len {
        return;
    }
    var s = 0.0;
    for (var m = 0u; m < sizes.sets; m++) {
        s += src[m * sizes.len + j];
    }
    dst[j] = s;
}
