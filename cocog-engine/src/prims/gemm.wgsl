// Tiled matrix product C = A·B for problems whose operands are read through functions, so one
// body serves plain matrices, the MLP's layers and implicit-GEMM convolutions (im2col gathered
// while loading a tile). The problem's prelude defines, before this body:
//   const A_K_FAST, B_K_FAST: bool   which index of A(m, k) and B(k, n) is contiguous in memory
//                                    (loading along it keeps neighbouring threads on
//                                    neighbouring addresses)
//   const SPLIT: bool                 K is cut into ranges whose partial products gemm_reduce
//                                    sums in a fixed order
//   const ONES_COLUMN: bool           B's last column is all ones and never loaded: the first
//                                    column of tiles sums A's rows into C's last column
//   const TY, TX, BK: u32             the workgroup's threads as TY rows × TX columns (each
//                                    computes 4×4 values: a tile of 4·TY × 4·TX) and the depth
//                                    of a staged slice
//   fn load_a(b, m, k) -> f32, fn load_b(b, k, n) -> f32   called only in range
//   fn epilogue(b, m, n, v)          stores a finished C(m, n) of batch b
//   fn store_partial(s, m, n, v), fn load_partial(s, m, n) -> f32   (no-ops without SPLIT)
// Batches: without SPLIT, gemm.batches independent products (grid z = batch); with SPLIT, a
// sum over batches as well as K (grid z = batch × parts + part of K), e.g. a weight gradient
// over every pixel of every image.


const WG: u32 = TY * TX;
const BM: u32 = 4u * TY;
const BN: u32 = 4u * TX;

// [BK][BM / 4] and [BK][BN / 4]: a thread's 4 rows (columns) of one k are one vec4.
var<workgroup> tile_a: array<vec4<f32>, BK * TY>;
var<workgroup> tile_b: array<vec4<f32>, BK * TX>;

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
    if wg.y * nwg.x + wg.x >= ((gemm.m + BM - 1u) / BM)
        * ((gemm.n - select(0u, 1u, ONES_COLUMN) + BN - 1u) / BN) {
        return;
    }
    let blk = block_of(wg, nwg);
    let m0 = blk.m0;
    let n0 = blk.n0;
    let z = blk.z;
    let b = blk.b;
    let k_begin = blk.k_begin;
    let k_end = blk.k_end;
    let tx = lid % TX;
    let ty = lid / TX;
    let cols = tile_cols();
    let sums_rows = ONES_COLUMN && n0 == 0u;
    var rows = vec4<f32>(0.0);
    var acc0 = vec4<f32>(0.0);
    var acc1 = vec4<f32>(0.0);
    var acc2 = vec4<f32>(0.0);
    var acc3 = vec4<f32>(0.0);
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
                va = load_a(b, m0 + mm, kb + kk);
            }
            tile_a[kk * TY + mm / 4u][mm % 4u] = va;
        }
        for (var e = lid; e < BN * BK; e += WG) {
            var nn = e % BN;
            var kk = e / BN;
            if B_K_FAST {
                kk = e % BK;
                nn = e / BK;
            }
            var vb = 0.0;
            if n0 + nn < cols && kb + kk < k_end {
                vb = load_b(b, kb + kk, n0 + nn);
            }
            tile_b[kk * TX + nn / 4u][nn % 4u] = vb;
        }
        workgroupBarrier();
        for (var kk = 0u; kk < BK; kk++) {
            let a = tile_a[kk * TY + ty];
            let bv = tile_b[kk * TX + tx];
            acc0 += a.x * bv;
            acc1 += a.y * bv;
            acc2 += a.z * bv;
            acc3 += a.w * bv;
            if sums_rows {
                rows += a;
            }
        }
        workgroupBarrier();
    }
    let m = m0 + 4u * ty;
    let n = n0 + 4u * tx;
    for (var j = 0u; j < 4u; j++) {
        if n + j < cols {
            finish(b, m, n + j, z, acc0[j]);
            finish(b, m + 1u, n + j, z, acc1[j]);
            finish(b, m + 2u, n + j, z, acc2[j]);
            finish(b, m + 3u, n + j, z, acc3[j]);
        }
    }
    if sums_rows && tx == 0u {
        finish(b, m, gemm.n - 1u, z, rows.x);
        finish(b, m + 1u, gemm.n - 1u, z, rows.y);
        finish(b, m + 2u, gemm.n - 1u, z, rows.z);
        finish(b, m + 3u, gemm.n - 1u, z, rows.w);
    }
}

// REDUCE_LANES invocations per C(m, n), each summing every REDUCE_LANES-th slice of the partial
// products in four running sums (so loads are in flight together), then their sums in a fixed
// order. One invocation per value left the h_θ weight gradients' sums (4160 values, 227
// slices) to 16 workgroups of long load chains.
// Four: the last sum below names each lane.
const REDUCE_LANES: u32 = 4u;
const REDUCE_VALUES: u32 = 256u / REDUCE_LANES;
var<workgroup> lane_sums: array<f32, 256>;

@compute @workgroup_size(256)
fn gemm_reduce(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    touch_all();
    // Neighbouring invocations take neighbouring values of one slice: coalesced loads.
    let lane = lid / REDUCE_VALUES;
    let t = (wg.y * nwg.x + wg.x) * REDUCE_VALUES + lid % REDUCE_VALUES;
    let inside = t < gemm.m * gemm.n;
    let m = t / gemm.n;
    let n = t % gemm.n;
    let slices = gemm.batches * gemm.parts;
    var s = vec4<f32>(0.0);
    if inside {
        var z = lane;
        let step = REDUCE_LANES;
        for (; z + 3u * step < slices; z += 4u * step) {
            s += vec4<f32>(load_partial(z, m, n), load_partial(z + step, m, n),
                load_partial(z + 2u * step, m, n), load_partial(z + 3u * step, m, n));
        }
        for (; z < slices; z += step) {
            s.x += load_partial(z, m, n);
        }
    }
    lane_sums[lid] = (s.x + s.y) + (s.z + s.w);
    workgroupBarrier();
    if inside && lane == 0u {
        let v = REDUCE_VALUES;
        epilogue(0u, m, n, (lane_sums[lid] + lane_sums[lid + v])
            + (lane_sums[lid + 2u * v] + lane_sums[lid + 3u * v]));
    }
}
