// gemm.wgsl's product on cooperative matrices (tensor cores): the same problem prelude (load_a,
// load_b, epilogue, store_partial, load_partial, A_K_FAST, B_K_FAST, SPLIT) and the same grid.
// The prelude also sets FR, the side of the adapter's square f16→f32 fragments (16 on NVIDIA,
// 8 on lavapipe; the type name coop_mat16x16 is rewritten to match), and SG, its fixed
// subgroup width, and the block's layout (gemm.rs's CoopBlock): GM × GN subgroups, taken to hold
// consecutive invocations (true on NVIDIA and lavapipe; Vulkan does not promise it), each
// accumulating WM × WN fragments of C in f32, from slices KF fragments deep staged in f16 (with
// PREFETCH, the next slice's loads are issued before the current slice's products). The
// host writes the accumulators' lines (named c_i_j: naga has no arrays of cooperative
// matrices) at the three marked places. SCALE_A and SCALE_B, also the
// prelude's, are powers of two applied before the f16 rounding and undone after: a gradient
// spread over every pixel lies below f16's normal range (6.1e-5) and would lose its digits or
// flush to zero. Under the Vulkan memory model, which cooperative matrices bring, naga 30's
// plain workgroup accesses are not formally ordered by barriers across invocations; drivers
// order them in practice, and the tests compare this product with the f32 one.

const WG: u32 = GM * GN * SG;
const BM: u32 = GM * WM * FR;
const BN: u32 = GN * WN * FR;
const BK: u32 = KF * FR;
const FRAG: u32 = FR * FR;

// Rows of the staged slices, PAD halves longer than their data (the host's CoopBlock::pad).
const SA: u32 = BK + PAD;
const SB: u32 = BN + PAD;
// [BM][SA] and [BK][SB]; then each subgroup's fragment of C on its way to `finish`.
var<workgroup> slice_a: array<f16, BM * SA>;
var<workgroup> slice_b: array<f16, BK * SB>;
var<workgroup> block_c: array<f32, GM * GN * FRAG>;

// Element e of a staged slice: (row, depth) of A's and (depth, column) of B's, in the block.
fn a_at(e: u32) -> vec2<u32> {
    if A_K_FAST {
        return vec2<u32>(e / BK, e % BK);
    }
    return vec2<u32>(e % BM, e / BM);
}
fn b_at(e: u32) -> vec2<u32> {
    if B_K_FAST {
        return vec2<u32>(e % BK, e / BK);
    }
    return vec2<u32>(e / BN, e % BN);
}
fn fetch_a(b: u32, m0: u32, kb: u32, k_end: u32, e: u32) -> f32 {
    let at = a_at(e);
    if m0 + at.x < gemm.m && kb + at.y < k_end {
        return load_a(b, m0 + at.x, kb + at.y) * SCALE_A;
    }
    return 0.0;
}
fn fetch_b(b: u32, n0: u32, kb: u32, k_end: u32, e: u32) -> f32 {
    let at = b_at(e);
    if n0 + at.y < gemm.n && kb + at.x < k_end {
        return load_b(b, kb + at.x, n0 + at.y) * SCALE_B;
    }
    return 0.0;
}
// Clamped as to_map clamps: an operand past f16's range would be inf, and inf × 0 (padding) NaN.
fn put_a(e: u32, v: f32) {
    let at = a_at(e);
    slice_a[at.x * SA + at.y] = f16(clamp(v, -65504.0, 65504.0));
}
fn put_b(e: u32, v: f32) {
    let at = b_at(e);
    slice_b[at.x * SB + at.y] = f16(clamp(v, -65504.0, 65504.0));
}

// With PREFETCH, each invocation holds its elements of the next slice in registers.
const EA: u32 = (BM * BK + WG - 1u) / WG;
const EB: u32 = (BN * BK + WG - 1u) / WG;
var<private> next_a: array<f32, EA>;
var<private> next_b: array<f32, EB>;
fn prefetch(lid: u32, b: u32, m0: u32, n0: u32, kb: u32, k_end: u32) {
    for (var t = 0u; t < EA; t++) {
        let e = lid + t * WG;
        if e < BM * BK {
            next_a[t] = fetch_a(b, m0, kb, k_end, e);
        }
    }
    for (var t = 0u; t < EB; t++) {
        let e = lid + t * WG;
        if e < BN * BK {
            next_b[t] = fetch_b(b, n0, kb, k_end, e);
        }
    }
}
fn stage(lid: u32) {
    for (var t = 0u; t < EA; t++) {
        let e = lid + t * WG;
        if e < BM * BK {
            put_a(e, next_a[t]);
        }
    }
    for (var t = 0u; t < EB; t++) {
        let e = lid + t * WG;
        if e < BN * BK {
            put_b(e, next_b[t]);
        }
    }
}

// Subgroup `sub`'s fragment at (m, n), just stored in block_c, through `finish`.
fn flush(sub: u32, lane: u32, b: u32, z: u32, m: u32, n: u32) {
    for (var i = lane; i < FRAG; i += SG) {
        let v = block_c[sub * FRAG + i] / (SCALE_A * SCALE_B);
        finish(b, m + i / FR, n + i % FR, z, v);
    }
}

@compute @workgroup_size(WG)
fn gemm_tile(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    touch_all();
    // Inline, not in block_of: naga's uniformity analysis takes a call's result as
    // non-uniform, and a return under it would put the cooperative products out of uniform
    // control flow.
    if wg.y * nwg.x + wg.x >= ((gemm.m + BM - 1u) / BM) * ((gemm.n + BN - 1u) / BN) {
        return;
    }
    let blk = block_of(wg, nwg);
    let m0 = blk.m0;
    let n0 = blk.n0;
    let z = blk.z;
    let b = blk.b;
    let k_begin = blk.k_begin;
    let k_end = blk.k_end;
    let sub = lid / SG;
    let lane = lid % SG;
    let sm = (sub / GN) * WM * FR;
    let sn = (sub % GN) * WN * FR;
    // ACCUMULATORS
    if PREFETCH {
        prefetch(lid, b, m0, n0, k_begin, k_end);
    }
    for (var kb = k_begin; kb < k_end; kb += BK) {
        if PREFETCH {
            // The slice fetched during the last products goes to workgroup memory, and the
            // next one's loads are issued before this one's products, to overlap them.
            stage(lid);
            workgroupBarrier();
            if kb + BK < k_end {
                prefetch(lid, b, m0, n0, kb + BK, k_end);
            }
        } else {
            for (var e = lid; e < BM * BK; e += WG) {
                put_a(e, fetch_a(b, m0, kb, k_end, e));
            }
            for (var e = lid; e < BN * BK; e += WG) {
                put_b(e, fetch_b(b, n0, kb, k_end, e));
            }
            workgroupBarrier();
        }
        for (var kk = 0u; kk < BK; kk += FR) {
            // PRODUCTS
        }
        workgroupBarrier();
    }
    // naga 30 emits no expression inside a coopStore call's arguments: bind them first.
    let mine = sub * FRAG;
    let m = m0 + sm;
    let n = n0 + sn;
    // STORES
}
