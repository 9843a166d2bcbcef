// Exclusive prefix sum of u32, in place, in blocks of 1024 (256 threads × 4 items).
// Larger inputs are handled by scanning the per-block totals recursively on the host side
// and adding them back with `add_block_offsets`.

struct Params {
    n: u32,
}

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read_write> data: array<u32>;
@group(0) @binding(2) var<storage, read_write> block_sums: array<u32>;

const THREADS: u32 = 256u;
const ITEMS: u32 = 4u;

var<workgroup> partial: array<u32, 256>;

fn block_index(wid: vec3<u32>, nwg: vec3<u32>) -> u32 {
    return wid.x + wid.y * nwg.x;
}

@compute @workgroup_size(256)
fn scan_blocks(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) tid: u32,
) {
    let block = block_index(wid, nwg);
    let base = block * THREADS * ITEMS + tid * ITEMS;
    var vals: array<u32, 4>;
    var total = 0u;
    for (var i = 0u; i < ITEMS; i++) {
        let idx = base + i;
        var v = 0u;
        if (idx < params.n) {
            v = data[idx];
        }
        vals[i] = total;
        total += v;
    }
    partial[tid] = total;
    workgroupBarrier();
    // Hillis–Steele inclusive scan of the per-thread totals.
    for (var off = 1u; off < THREADS; off <<= 1u) {
        var v = partial[tid];
        if (tid >= off) {
            v += partial[tid - off];
        }
        workgroupBarrier();
        partial[tid] = v;
        workgroupBarrier();
    }
    var prefix = 0u;
    if (tid > 0u) {
        prefix = partial[tid - 1u];
    }
    for (var i = 0u; i < ITEMS; i++) {
        let idx = base + i;
        if (idx < params.n) {
            data[idx] = vals[i] + prefix;
        }
    }
    if (tid == THREADS - 1u) {
        block_sums[block] = partial[tid];
    }
}

@compute @workgroup_size(256)
fn add_block_offsets(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) tid: u32,
) {
    let block = block_index(wid, nwg);
    let offset = block_sums[block];
    let base = block * THREADS * ITEMS + tid * ITEMS;
    for (var i = 0u; i < ITEMS; i++) {
        let idx = base + i;
        if (idx < params.n) {
            data[idx] += offset;
        }
    }
}
