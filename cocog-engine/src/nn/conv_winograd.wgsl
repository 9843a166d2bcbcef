// F's 3×3 convolutions (stride 1, zero padding 1) by Winograd's minimal filtering F(2×2, 3×3):
// an output tile of 2×2 pixels is Aᵀ [Σ_c (G g_c Gᵀ) ⊙ (Bᵀ d_c B)] A, where d_c is the tile's
// 4×4 input patch of channel c and g_c the 3×3 kernel. Per tile and output channel that is
// 16 products per summed channel where the direct convolution needs 36, so the 16 positions ξ
// of the 4×4 transformed tile are 16 matrix products of (outputs × channels) by
// (channels × tiles), each a quarter of the direct one's depth.
//
// `winograd_weights` writes U_ξ = (G g Gᵀ)_ξ as [ξ][summed channel][output channel] (the
// weights change every step, so every pass transforms them first). `winograd_conv` gives a
// workgroup 64 output channels × a block of 8×8 tiles (16×16 pixels) of one image; it walks
// ξ outermost, so it holds one 64×64 block of the product at a time (a thread's 4 channels ×
// 4 tiles), and folds each finished ξ into its 2×2 outputs at once (Aᵀ's entries are 0 and
// ±1). Bᵀ d B is computed while a slice of channels loads: each of its entries is a signed sum
// of 4 patch values.
//
// The same kernels compute a 3×3 layer's input gradient, the convolution of the output
// gradient with the kernel transposed (in ↔ out) and flipped (TRANSPOSED). The prelude
// defines in_t, out_t and to_out (see conv_tile.wgsl). Maps are [image][channel][y][x].

@group(0) @binding(1) var<storage, read> params: array<f32>;
// [ξ][c][m]: written by winograd_weights, read by winograd_conv.
@group(0) @binding(2) var<storage, read_write> u_mat: array<f32>;
@group(0) @binding(3) var<storage, read> input: array<in_t>;
@group(0) @binding(4) var<storage, read_write> output: array<out_t>;

// The kernel this pass correlates with: tap k = 3·ky + kx of output m, summed channel c.
fn kernel_tap(m: u32, c: u32, k: u32) -> f32 {
    if wn.transposed == 1u {
        // The layer's weights are W[c][m][tap] with m its input channels.
        return params[wn.w_off + (c * wn.outputs + m) * 9u + (8u - k)];
    }
    return params[wn.w_off + (m * wn.summed + c) * 9u + k];
}

@compute @workgroup_size(64)
fn winograd_weights(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
) {
    // dispatch_1d folds a long grid into y.
    let t = gid.y * nwg.x * 64u + gid.x;
    if t >= wn.outputs * wn.summed {
        return;
    }
    let m = t % wn.outputs;
    let c = t / wn.outputs;
    // G g: column kx of g through G, then each row of the result through G again (· Gᵀ).
    var cols: array<vec4<f32>, 3>;
    for (var kx = 0u; kx < 3u; kx++) {
        cols[kx] = g_times(vec3<f32>(
            kernel_tap(m, c, kx),
            kernel_tap(m, c, 3u + kx),
            kernel_tap(m, c, 6u + kx),
        ));
    }
    for (var i = 0u; i < 4u; i++) {
        let row = g_times(vec3<f32>(cols[0][i], cols[1][i], cols[2][i]));
        for (var j = 0u; j < 4u; j++) {
            u_mat[((i * 4u + j) * wn.summed + c) * wn.outputs + m] = row[j];
        }
    }
}

const WG: u32 = 256u;
// Output channels per workgroup, tiles per side of its block, channels per staged slice.
const BM: u32 = 64u;
const BT: u32 = 8u;
const BN: u32 = BT * BT;
const BK: u32 = 32u;

// [k][m / 4] and [k][tile / 4]: a thread's 4 channels (tiles) of one k are one vec4.
var<workgroup> tile_a: array<vec4<f32>, BK * BM / 4u>;
var<workgroup> tile_b: array<vec4<f32>, BK * BN / 4u>;

fn store_tile(b: u32, m: u32, tile: vec2<u32>, v: vec4<f32>) {
    if m >= wn.outputs || tile.x >= wn.tiles_y || tile.y >= wn.tiles_x {
        return;
    }
    var bias = 0.0;
    if wn.bias_off != 0xffffffffu && wn.transposed == 0u {
        bias = params[wn.bias_off + m];
    }
    let plane = (b * wn.outputs + m) * wn.height;
    let y = 2u * tile.x;
    let x = 2u * tile.y;
    let right = x + 1u < wn.width;
    output[(plane + y) * wn.width + x] = to_out(v.x + bias);
    if right {
        output[(plane + y) * wn.width + x + 1u] = to_out(v.y + bias);
    }
    if y + 1u < wn.height {
        output[(plane + y + 1u) * wn.width + x] = to_out(v.z + bias);
        if right {
            output[(plane + y + 1u) * wn.width + x + 1u] = to_out(v.w + bias);
        }
    }
}

@compute @workgroup_size(WG)
fn winograd_conv(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    // Grid: x blocks of tile columns, y blocks of tile rows × 64-channel blocks, z images.
    let blocks_y = (wn.tiles_y + BT - 1u) / BT;
    let t0 = vec2<u32>((wg.y % blocks_y) * BT, wg.x * BT);
    let m0 = (wg.y / blocks_y) * BM;
    let b = wg.z;
    // Thread: channels m0 + 4·ty + r, tiles 4·tx + t of the block (one row of the block).
    let ty = lid / 16u;
    let tx = lid % 16u;
    // y[4·r + t]: the 2×2 outputs (row-major) of channel r and tile t.
    var y = array<vec4<f32>, 16>();
    // The tile this invocation stages in every slice (WG is a multiple of BN).
    let n_staged = lid % BN;
    let tile_staged = vec2<u32>(t0.x + n_staged / BT, t0.y + n_staged % BT);
    for (var xi = 0u; xi < 16u; xi++) {
        let taps = taps_of(tile_staged, bt_row(xi / 4u), bt_row(xi % 4u));
        var acc0 = vec4<f32>(0.0);
        var acc1 = vec4<f32>(0.0);
        var acc2 = vec4<f32>(0.0);
        var acc3 = vec4<f32>(0.0);
        for (var c0 = 0u; c0 < wn.summed; c0 += BK) {
            for (var e = lid; e < BK * BM; e += WG) {
                let mm = e % BM;
                let kk = e / BM;
                var va = 0.0;
                if m0 + mm < wn.outputs && c0 + kk < wn.summed {
                    va = u_mat[(xi * wn.summed + c0 + kk) * wn.outputs + m0 + mm];
                }
                tile_a[kk * (BM / 4u) + mm / 4u][mm % 4u] = va;
            }
            for (var e = lid; e < BK * BN; e += WG) {
                let kk = e / BN;
                var vb = 0.0;
                if c0 + kk < wn.summed {
                    vb = transformed_input(b, c0 + kk, taps);
                }
                tile_b[kk * (BN / 4u) + n_staged / 4u][n_staged % 4u] = vb;
            }
            workgroupBarrier();
            for (var kk = 0u; kk < BK; kk++) {
                let a = tile_a[kk * (BM / 4u) + ty];
                let bv = tile_b[kk * (BN / 4u) + tx];
                acc0 += a.x * bv;
                acc1 += a.y * bv;
                acc2 += a.z * bv;
                acc3 += a.w * bv;
            }
            workgroupBarrier();
        }
        // Output (r, s) of a tile takes Aᵀ[r][i]·Aᵀ[s][j] of position ξ = (i, j).
        let ai = at_col(xi / 4u);
        let aj = at_col(xi % 4u);
        let k = vec4<f32>(ai.x * aj.x, ai.x * aj.y, ai.y * aj.x, ai.y * aj.y);
        // Constant indices only, here and below: an array indexed by a variable may be kept in
        // memory instead of registers.
        y[0] += k * acc0.x;
        y[1] += k * acc0.y;
        y[2] += k * acc0.z;
        y[3] += k * acc0.w;
        y[4] += k * acc1.x;
        y[5] += k * acc1.y;
        y[6] += k * acc1.z;
        y[7] += k * acc1.w;
        y[8] += k * acc2.x;
        y[9] += k * acc2.y;
        y[10] += k * acc2.z;
        y[11] += k * acc2.w;
        y[12] += k * acc3.x;
        y[13] += k * acc3.y;
        y[14] += k * acc3.z;
        y[15] += k * acc3.w;
    }
    // The thread's 4 tiles lie along one row of the block.
    let n = 4u * tx;
    let tile0 = vec2<u32>(t0.x + n / BT, t0.y + n % BT);
    let tile1 = tile0 + vec2<u32>(0u, 1u);
    let tile2 = tile0 + vec2<u32>(0u, 2u);
    let tile3 = tile0 + vec2<u32>(0u, 3u);
    let m = m0 + 4u * ty;
    store_tile(b, m + 0u, tile0, y[0]);
    store_tile(b, m + 0u, tile1, y[1]);
    store_tile(b, m + 0u, tile2, y[2]);
    store_tile(b, m + 0u, tile3, y[3]);
    store_tile(b, m + 1u, tile0, y[4]);
    store_tile(b, m + 1u, tile1, y[5]);
    store_tile(b, m + 1u, tile2, y[6]);
    store_tile(b, m + 1u, tile3, y[7]);
    store_tile(b, m + 2u, tile0, y[8]);
    store_tile(b, m + 2u, tile1, y[9]);
    store_tile(b, m + 2u, tile2, y[10]);
    store_tile(b, m + 2u, tile3, y[11]);
    store_tile(b, m + 3u, tile0, y[12]);
    store_tile(b, m + 3u, tile1, y[13]);
    store_tile(b, m + 3u, tile2, y[14]);
    store_tile(b, m + 3u, tile3, y[15]);
}
