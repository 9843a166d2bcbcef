// gemm.wgsl's product on cooperative matrices (tensor cores): the same problem prelude (load_a,
// load_b, epilogue, store_partial, load_partial, A_K_FAST, B_K_FAST, SPLIT) and the same grid,
// with 64×64 blocks of C from 32-deep slices. A workgroup is four 32-wide subgroups, taken to
// hold consecutive invocations (as on NVIDIA; Vulkan does not promise it), each accumulating a
// 32×32 quarter in f32 from slices staged in f16. The prelude also defines SCALE_A and SCALE_B,
// powers of two applied before the f16 rounding and undone after: a gradient spread over every
// pixel lies below f16's normal range (6.1e-5) and would lose its digits or flush to zero.
// Under the Vulkan memory model, which cooperative matrices bring, naga 30's plain workgroup
// accesses are not formally ordered by barriers across invocations; drivers order them in
// practice, and the tests compare this product with the f32 one.

const WG: u32 = 128u;
const BM: u32 = 64u;
const BN: u32 = 64u;
const BK: u32 = 32u;

// [BM][BK] and [BK][BN]; then each subgroup's 16×16 block of C on its way to `finish`.
var<workgroup> slice_a: array<f16, 2048>;
var<workgroup> slice_b: array<f16, 2048>;
var<workgroup> block_c: array<f32, 1024>;

// Subgroup `sub`'s 16×16 block at (m, n), just stored in block_c, through `finish`.
fn flush(sub: u32, lane: u32, b: u32, z: u32, m: u32, n: u32) {
    for (var i = lane; i < 256u; i += 32u) {
        let v = block_c[sub * 256u + i] / (SCALE_A * SCALE_B);
        finish(b, m + i / 16u, n + i % 16u, z, v);
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
    let sub = lid / 32u;
    let lane = lid % 32u;
    let sm = (sub / 2u) * 32u;
    let sn = (sub % 2u) * 32u;
    var c00 = coop_mat16x16<f32, C>();
    var c01 = coop_mat16x16<f32, C>();
    var c10 = coop_mat16x16<f32, C>();
    var c11 = coop_mat16x16<f32, C>();
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
        for (var kk = 0u; kk < BK; kk += 16u) {
            let a0 = coopLoadT<coop_mat16x16<f16, A>>(&slice_a[sm * BK + kk], BK);
            let a1 = coopLoadT<coop_mat16x16<f16, A>>(&slice_a[(sm + 16u) * BK + kk], BK);
            let b0 = coopLoadT<coop_mat16x16<f16, B>>(&slice_b[kk * BN + sn], BN);
            let b1 = coopLoadT<coop_mat16x16<f16, B>>(&slice_b[kk * BN + sn + 16u], BN);
            c00 = coopMultiplyAdd(a0, b0, c00);
            c01 = coopMultiplyAdd(a0, b1, c01);
            c10 = coopMultiplyAdd(a1, b0, c10);
            c11 = coopMultiplyAdd(a1, b1, c11);
        }
        workgroupBarrier();
    }
    // naga 30 emits no expression inside a coopStore call's arguments: bind them first.
    let mine = sub * 256u;
    let m = m0 + sm;
    let n = n0 + sn;
    coopStoreT(c00, &block_c[mine], 16u);
    workgroupBarrier();
    flush(sub, lane, b, z, m, n);
    workgroupBarrier();
    coopStoreT(c01, &block_c[mine], 16u);
    workgroupBarrier();
    flush(sub, lane, b, z, m, n + 16u);
    workgroupBarrier();
    coopStoreT(c10, &block_c[mine], 16u);
    workgroupBarrier();
    flush(sub, lane, b, z, m + 16u, n);
    workgroupBarrier();
    coopStoreT(c11, &block_c[mine], 16u);
    workgroupBarrier();
    flush(sub, lane, b, z, m + 16u, n + 16u);
}
