// The densified rows of one parameter group (densify.wgsl): each surviving candidate's row,
// read from a copy of the group taken before, written to its scanned slot; `rows_out` is the
// group itself, so the copy is what makes the move in place safe.

const KIND_KEEP: u32 = 0u;
const KIND_SPLIT: u32 = 2u;

struct Gather {
    // Floats per row of this group.
    stride: u32,
    // 0: copy the source row; 1: means (split children take their sampled mean);
    // 2: log-scales (split children take theirs); 3: Adam moments (new Gaussians start at 0).
    mode: u32,
    bound: u32,
    // Rows from the new count up to `bound` are buried: their first float set to
    // `bury_first`, the others to `bury_rest`. The trainer may render and optimise up to
    // `bound` rows until the count reaches the CPU, so buried rows must be finite everywhere
    // (CoCoGaussian's h_θ reads every row), draw nothing and move nothing.
    bury_first: f32,
    bury_rest: f32,
    pad0: u32,
    pad1: u32,
    pad2: u32,
}

@group(0) @binding(0) var<uniform> params: Gather;
@group(0) @binding(1) var<storage, read> candidates: array<u32>;
@group(0) @binding(2) var<storage, read> child_shapes: array<f32>;
@group(0) @binding(3) var<storage, read> survive_slots: array<u32>;
@group(0) @binding(4) var<storage, read> rows_in: array<f32>;
@group(0) @binding(5) var<storage, read_write> rows_out: array<f32>;

@compute @workgroup_size(256)
fn gather_rows(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let slot = gid.x + gid.y * nwg.x * 256u;
    if (slot >= params.bound) {
        return;
    }
    let stride = params.stride;
    if (slot >= survive_slots[params.bound]) {
        rows_out[slot * stride] = params.bury_first;
        for (var k = 1u; k < stride; k++) {
            rows_out[slot * stride + k] = params.bury_rest;
        }
    }
    if (survive_slots[slot + 1u] == survive_slots[slot]) {
        return;
    }
    let word = candidates[slot];
    let src = word & 0x3fffffffu;
    let kind = word >> 30u;
    let dst = survive_slots[slot] * stride;
    let mode = params.mode;
    for (var k = 0u; k < stride; k++) {
        var v = rows_in[src * stride + k];
        if (mode == 3u && kind != KIND_KEEP) {
            v = 0.0;
        } else if (mode == 1u && kind == KIND_SPLIT) {
            v = child_shapes[6u * slot + k];
        } else if (mode == 2u && kind == KIND_SPLIT) {
            v = child_shapes[6u * slot + 3u + k];
        }
        rows_out[dst + k] = v;
    }
}
