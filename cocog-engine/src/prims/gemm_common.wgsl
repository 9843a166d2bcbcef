// What gemm.wgsl (f32 tiles) and gemm_coop.wgsl (cooperative matrices) share: the problem's
// dimensions, the block of C a workgroup owns and where a finished value goes. Both take the
// problem prelude gemm.wgsl describes; BM, BN and BK are each body's own.

struct GemmDims {
    m: u32,
    n: u32,
    // K per batch.
    k: u32,
    // K per part (a multiple of BK) and parts per batch (1 without SPLIT).
    k_split: u32,
    parts: u32,
    batches: u32,
    // Problem parameters, named by the prelude.
    u0: u32,
    u1: u32,
    u2: u32,
    u3: u32,
    u4: u32,
    u5: u32,
    u6: u32,
    u7: u32,
    u8: u32,
    u9: u32,
}

@group(0) @binding(0) var<uniform> gemm: GemmDims;

// (n / d, n % d) for d ≥ 1 through f32 and one correction: CPU adapters scalarise integer
// division, which then dominates a loader. Exact while n / d < 2^23.
fn divmod(n: u32, d: u32) -> vec2<u32> {
    var q = u32(f32(n) / f32(d));
    let qd = q * d;
    if qd > n {
        q -= 1u;
    } else if n - qd >= d {
        q += 1u;
    }
    return vec2<u32>(q, n - q * d);
}

// Never runs (batches ≥ 1), but makes both entry points use every binding of the problem, so
// one bind group serves both.
fn touch_all() {
    if gemm.batches == 0u {
        store_partial(0u, 0u, 0u, load_partial(0u, 0u, 0u));
        epilogue(0u, 0u, 0u, load_a(0u, 0u, 0u) + load_b(0u, 0u, 0u));
    }
}

// The columns of C that tiles cover: with ONES_COLUMN, B's last column is all ones (a bias's
// gradient), and its products are A's row sums, which the first column of tiles adds on the
// side instead of a whole further column of tiles multiplying by one.
fn tile_cols() -> u32 {
    return gemm.n - select(0u, 1u, ONES_COLUMN);
}

fn finish(b: u32, m: u32, n: u32, z: u32, v: f32) {
    if m < gemm.m && n < gemm.n {
        if SPLIT {
            store_partial(z, m, n, v);
        } else {
            epilogue(b, m, n, v);
        }
    }
}

// The block of C workgroup `wg` computes, and its range of K: the grid is tiles of BM × BN
// (folded into x and y) by batch × part of K (z). The caller skips workgroups past the last
// tile (a grid folded into y has some).
struct Block {
    m0: u32,
    n0: u32,
    // The batch and the slot of its partial products.
    b: u32,
    z: u32,
    k_begin: u32,
    k_end: u32,
}

fn block_of(wg: vec3<u32>, nwg: vec3<u32>) -> Block {
    let tiles_n = (tile_cols() + BN - 1u) / BN;
    let tile = wg.y * nwg.x + wg.x;
    let part = wg.z % gemm.parts;
    let k_begin = part * gemm.k_split;
    return Block(
        (tile / tiles_n) * BM,
        (tile % tiles_n) * BN,
        wg.z / gemm.parts,
        wg.z,
        k_begin,
        min(gemm.k, k_begin + gemm.k_split),
    );
}
