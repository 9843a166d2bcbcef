// Stable LSD radix sort of (u32 key, u32 value) pairs, 8 bits per pass.
// Per pass: `count_digits` builds a digit-major histogram [256][blocks] of each block of 1024
// pairs, PrefixSum turns it into each (digit, block)'s first output position, and `scatter`
// sorts its block by the pass's digit in workgroup memory (stable splits, 3 bits a round)
// and writes each pair to its (digit, block) position plus its rank among the block's pairs
// of that digit. The local sort keeps equal digits in input order (stability is what makes LSD
// radix correct) and writes each digit's run of a block to consecutive addresses.
// A first pass may drop the pairs whose key is 0xffffffff (culled Gaussians): they take a 257th
// digit after every other, are not written, and the count of the rest lands in `kept`, so the
// later passes sort only those.

struct Params {
    // The pair count, or with a GPU count its upper bound (the buffers' capacity).
    n: u32,
    shift: u32,
    num_blocks: u32,
    // Where in `count_src` the GPU count is, or 0xffffffff when `n` is exact.
    count_at: u32,
    // The pass's digit mask: 255, or fewer bits on a last pass that sorts fewer than 8.
    mask: u32,
    // 1: this pass drops keys of 0xffffffff and writes how many pairs it kept.
    drop: u32,
    pad1: u32,
    pad2: u32,
}

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> keys_in: array<u32>;
@group(0) @binding(2) var<storage, read_write> histogram: array<u32>;
@group(0) @binding(3) var<storage, read> values_in: array<u32>;
@group(0) @binding(4) var<storage, read_write> keys_out: array<u32>;
@group(0) @binding(5) var<storage, read_write> values_out: array<u32>;
@group(0) @binding(6) var<storage, read> count_src: array<u32>;
@group(0) @binding(7) var<storage, read_write> kept: array<u32>;

fn num_pairs() -> u32 {
    if (params.count_at == 0xffffffffu) {
        return params.n;
    }
    return min(params.n, count_src[params.count_at]);
}

const THREADS: u32 = 256u;
const ITEMS: u32 = 4u;
const BLOCK: u32 = 1024u;
const DIGITS: u32 = 256u;
const DROPPED: u32 = 0xffffffffu;

// The pass's digit of `key`: DIGITS, past every other, for a key this pass drops.
fn digit_of(key: u32) -> u32 {
    if (params.drop == 1u && key == DROPPED) {
        return DIGITS;
    }
    return (key >> params.shift) & params.mask;
}

fn block_index(wid: vec3<u32>, nwg: vec3<u32>) -> u32 {
    return wid.x + wid.y * nwg.x;
}

var<workgroup> digit_counts: array<atomic<u32>, 257>;

@compute @workgroup_size(256)
fn count_digits(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) tid: u32,
) {
    let block = block_index(wid, nwg);
    let n = num_pairs();
    atomicStore(&digit_counts[tid], 0u);
    if (tid == 0u) {
        atomicStore(&digit_counts[DIGITS], 0u);
    }
    workgroupBarrier();
    for (var i = 0u; i < ITEMS; i++) {
        let idx = block * BLOCK + i * THREADS + tid;
        if (idx < n) {
            atomicAdd(&digit_counts[digit_of(keys_in[idx])], 1u);
        }
    }
    workgroupBarrier();
    if (block < params.num_blocks) {
        histogram[tid * params.num_blocks + block] = atomicLoad(&digit_counts[tid]);
        if (tid == 0u && params.drop == 1u) {
            histogram[DIGITS * params.num_blocks + block] = atomicLoad(&digit_counts[DIGITS]);
        }
    }
}

var<workgroup> local_keys: array<u32, 1024>;
var<workgroup> local_values: array<u32, 1024>;
// Per thread, its counts of each of a round's 8 buckets, two 16-bit fields a word.
var<workgroup> sums: array<vec4<u32>, 256>;
// Per digit, its first position in the locally sorted block.
var<workgroup> starts: array<u32, 257>;

// The local sort splits the block on ROUND_BITS bits at a time (stable counting sorts of 8
// buckets): three rounds and their scans for an 8- or 9-bit digit, where one-bit splits took
// eight or nine, each with a scan's 17 barriers. Counts and positions stay below 2^16 (a block
// is 1024), so each vec4<u32> holds 8 of them as 16-bit fields and adds them all at once.
const ROUND_BITS: u32 = 3u;
const BUCKETS: u32 = 1u << ROUND_BITS;

// The bucket of `key` in the round at bit `shift`.
fn bucket(key: u32, shift: u32) -> u32 {
    return (digit_of(key) >> shift) & (BUCKETS - 1u);
}

// Field b of 8 packed 16-bit fields.
fn field(p: vec4<u32>, b: u32) -> u32 {
    return (p[b >> 1u] >> (16u * (b & 1u))) & 0xffffu;
}

// 1 in field b.
fn unit(b: u32) -> vec4<u32> {
    var u = vec4<u32>(0u);
    u[b >> 1u] = 1u << (16u * (b & 1u));
    return u;
}

// Inclusive sum of `v` over threads 0..=tid, field by field.
fn scan(tid: u32, v: vec4<u32>) -> vec4<u32> {
    sums[tid] = v;
    workgroupBarrier();
    for (var off = 1u; off < THREADS; off <<= 1u) {
        var s = sums[tid];
        if (tid >= off) {
            s += sums[tid - off];
        }
        workgroupBarrier();
        sums[tid] = s;
        workgroupBarrier();
    }
    return sums[tid];
}

@compute @workgroup_size(256)
fn scatter(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) tid: u32,
) {
    let block = block_index(wid, nwg);
    let n = num_pairs();
    let base = block * BLOCK;
    var valid = 0u;
    if (n > base) {
        valid = min(BLOCK, n - base);
    }
    // Pairs past the count take the largest digit: being last in the input, the stable local
    // sort leaves them last, where nothing writes them out.
    var pad_key = params.mask << params.shift;
    if (params.drop == 1u) {
        pad_key = DROPPED;
    }
    if (block == 0u && tid == 0u && params.drop == 1u) {
        // The exclusive scan's start of the dropped row: every kept pair comes before it.
        kept[0] = histogram[DIGITS * params.num_blocks];
    }
    // Blocks wholly past a GPU count (a capacity's, or the kept Gaussians') have nothing to
    // sort: without this they would sort a block of padding.
    if (valid == 0u) {
        return;
    }
    for (var i = 0u; i < ITEMS; i++) {
        let p = i * THREADS + tid;
        if (p < valid) {
            local_keys[p] = keys_in[base + p];
            local_values[p] = values_in[base + p];
        } else {
            local_keys[p] = pad_key;
            local_values[p] = 0u;
        }
    }
    workgroupBarrier();
    // Thread tid owns positions 4·tid … 4·tid + 3 during the rounds.
    // A dropping pass sorts one more bit: its digits run to DIGITS.
    let bits = countOneBits(params.mask) + params.drop;
    for (var shift = 0u; shift < bits; shift += ROUND_BITS) {
        var k: array<u32, 4>;
        var v: array<u32, 4>;
        var own = vec4<u32>(0u);
        for (var i = 0u; i < ITEMS; i++) {
            k[i] = local_keys[ITEMS * tid + i];
            v[i] = local_values[ITEMS * tid + i];
            own += unit(bucket(k[i], shift));
        }
        let through = scan(tid, own);
        let total = sums[THREADS - 1u];
        workgroupBarrier();
        // Each bucket's run starts after the smaller buckets' totals; within it, this thread's
        // items come after the earlier threads' (an inclusive scan less its own count never
        // borrows across fields).
        var at = through - own;
        var run = 0u;
        for (var b = 0u; b < BUCKETS; b++) {
            at[b >> 1u] += run << (16u * (b & 1u));
            run += field(total, b);
        }
        for (var i = 0u; i < ITEMS; i++) {
            let b = bucket(k[i], shift);
            let p = field(at, b);
            local_keys[p] = k[i];
            local_values[p] = v[i];
            at += unit(b);
        }
        workgroupBarrier();
    }
    for (var i = 0u; i < ITEMS; i++) {
        let p = i * THREADS + tid;
        let d = digit_of(local_keys[p]);
        if (p == 0u || digit_of(local_keys[p - 1u]) != d) {
            starts[d] = p;
        }
    }
    workgroupBarrier();
    for (var i = 0u; i < ITEMS; i++) {
        let p = i * THREADS + tid;
        let d = digit_of(local_keys[p]);
        if (p < valid && d < DIGITS) {
            let dst = histogram[d * params.num_blocks + block] + p - starts[d];
            keys_out[dst] = local_keys[p];
            values_out[dst] = local_values[p];
        }
    }
}
