// Stable LSD radix sort of (u32 key, u32 value) pairs, 4 bits per pass.
// Per pass: `count_digits` builds a digit-major histogram [16][blocks], the host scans it
// exclusively, and `scatter` moves each block's elements to their global positions. The
// scatter ranks elements within a block by a workgroup scan over 16 packed 16-bit counters,
// so equal digits keep their input order (stability is what makes LSD radix correct).

struct Params {
    // The pair count, or with a GPU count its upper bound (the buffers' capacity).
    n: u32,
    shift: u32,
    num_blocks: u32,
    // Where in `count_src` the GPU count is, or 0xffffffff when `n` is exact.
    count_at: u32,
}

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> keys_in: array<u32>;
@group(0) @binding(2) var<storage, read_write> histogram: array<u32>;
@group(0) @binding(3) var<storage, read> values_in: array<u32>;
@group(0) @binding(4) var<storage, read_write> keys_out: array<u32>;
@group(0) @binding(5) var<storage, read_write> values_out: array<u32>;
@group(0) @binding(6) var<storage, read> count_src: array<u32>;

fn num_pairs() -> u32 {
    if (params.count_at == 0xffffffffu) {
        return params.n;
    }
    return min(params.n, count_src[params.count_at]);
}

const THREADS: u32 = 256u;
const ITEMS: u32 = 4u;
const BLOCK: u32 = 1024u;
const DIGITS: u32 = 16u;

var<workgroup> digit_counts: array<atomic<u32>, 16>;
// Two vec4 halves of eight u32 words, each packing two 16-bit digit counters.
var<workgroup> scan_lo: array<vec4<u32>, 256>;
var<workgroup> scan_hi: array<vec4<u32>, 256>;
var<workgroup> running: array<u32, 16>;

fn block_index(wid: vec3<u32>, nwg: vec3<u32>) -> u32 {
    return wid.x + wid.y * nwg.x;
}

@compute @workgroup_size(256)
fn count_digits(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) tid: u32,
) {
    let block = block_index(wid, nwg);
    let n = num_pairs();
    if (tid < DIGITS) {
        atomicStore(&digit_counts[tid], 0u);
    }
    workgroupBarrier();
    for (var i = 0u; i < ITEMS; i++) {
        let idx = block * BLOCK + i * THREADS + tid;
        if (idx < n) {
            atomicAdd(&digit_counts[(keys_in[idx] >> params.shift) & 15u], 1u);
        }
    }
    workgroupBarrier();
    if (tid < DIGITS && block < params.num_blocks) {
        histogram[tid * params.num_blocks + block] = atomicLoad(&digit_counts[tid]);
    }
}

fn lane(lo: vec4<u32>, hi: vec4<u32>, digit: u32) -> u32 {
    let word = digit >> 1u;
    var w: u32;
    if (word < 4u) {
        w = lo[word];
    } else {
        w = hi[word - 4u];
    }
    return (w >> ((digit & 1u) * 16u)) & 0xffffu;
}

@compute @workgroup_size(256)
fn scatter(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) tid: u32,
) {
    let block = block_index(wid, nwg);
    let n = num_pairs();
    if (tid < DIGITS) {
        running[tid] = 0u;
    }
    for (var i = 0u; i < ITEMS; i++) {
        let idx = block * BLOCK + i * THREADS + tid;
        let valid = idx < n;
        var key = 0u;
        var digit = DIGITS;
        if (valid) {
            key = keys_in[idx];
            digit = (key >> params.shift) & 15u;
        }
        var lo = vec4<u32>(0u);
        var hi = vec4<u32>(0u);
        if (valid) {
            let one = 1u << ((digit & 1u) * 16u);
            let word = digit >> 1u;
            if (word < 4u) {
                lo[word] = one;
            } else {
                hi[word - 4u] = one;
            }
        }
        scan_lo[tid] = lo;
        scan_hi[tid] = hi;
        workgroupBarrier();
        for (var off = 1u; off < THREADS; off <<= 1u) {
            var a = scan_lo[tid];
            var b = scan_hi[tid];
            if (tid >= off) {
                a += scan_lo[tid - off];
                b += scan_hi[tid - off];
            }
            workgroupBarrier();
            scan_lo[tid] = a;
            scan_hi[tid] = b;
            workgroupBarrier();
        }
        if (valid) {
            let rank = lane(scan_lo[tid], scan_hi[tid], digit) - 1u;
            let dst = histogram[digit * params.num_blocks + block] + running[digit] + rank;
            keys_out[dst] = key;
            values_out[dst] = values_in[idx];
        }
        workgroupBarrier();
        if (tid < DIGITS) {
            running[tid] += lane(scan_lo[THREADS - 1u], scan_hi[THREADS - 1u], tid);
        }
        workgroupBarrier();
    }
}
