// gemm.wgsl's product on cooperative matrices (tensor cores): the same problem prelude (load_a,
// load_b, epilogue, store_partial, load_partial, A_K_FAST, B_K_FAST, SPLIT) and the same grid.
// The prelude also sets FR, the side of the adapter's square f16→f32 fragments (16 on NVIDIA,
// 8 on lavapipe; the type name coop_mat16x16 is rewritten to match), and SG, its fixed
// subgroup width, and the block's layout (gemm.rs's CoopBlock): GM × GN subgroups, taken to hold
// consecutive invocations (true on NVIDIA and lavapipe; Vulkan does not promise it), each
// accumulating WM × WN fragments of C in f32, from slices KF fragments deep staged in f16. The
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

// [BM][BK] and [BK][BN]; then each subgroup's fragment of C on its way to `finish`.
var<workgroup> slice_a: array<f16, BM * BK>;
var<workgroup> slice_b: array<f16, BK * BN>;
var<workgroup> block_c: array<f32, GM * GN * FRAG>;

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
    for (var kb = k_begin; kb < k_end; kb += BK) {
        for (var e = lid; e < BM * BK; e += WG) {
            var mm = e % BM;
            var kk = e / BM;
            if A_K_FAST {
                kk = e % BK;
                mm = e / BK;
            }
            var va = 0.0;
            if m0 + mm < gemm.m && kb + kk < k_end {
                va = load_a(b, m0 + mm, kb + kk) * SCALE_A;
            }
            // Clamped as to_map clamps: an operand past f16's range would be inf, and inf × 0
            // (padding) NaN.
            slice_a[mm * BK + kk] = f16(clamp(va, -65504.0, 65504.0));
        }
        for (var e = lid; e < BN * BK; e += WG) {
            var nn = e % BN;
            var kk = e / BN;
            if B_K_FAST {
                kk = e % BK;
                nn = e / BK;
            }
            var vb = 0.0;
            if n0 + nn < gemm.n && kb + kk < k_end {
                vb = load_b(b, kb + kk, n0 + nn) * SCALE_B;
            }
            slice_b[kk * BN + nn] = f16(clamp(vb, -65504.0, 65504.0));
        }
        workgroupBarrier();
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
