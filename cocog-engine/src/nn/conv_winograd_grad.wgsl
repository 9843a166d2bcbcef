// The weight and bias gradients of a 3×3 layer computed as conv_winograd.wgsl computes its
// forward. With M_ξ = U_ξ V_ξ per position ξ = (i, j) of the transformed tile and
// Y = Aᵀ M A per tile, the loss gradient reaches U_ξ as ∂U_ξ = Σ_tiles ∂M_ξ V_ξᵀ with
// ∂M = A ∂Y Aᵀ, and the kernel as ∂g = Gᵀ ∂U G: 16 products of (outputs × tiles) by
// (tiles × channels), summed over every tile of every image, where the implicit GEMM sums
// 9 taps × channels columns over every pixel.
//
// `winograd_weight_part` gives a workgroup one ξ, one range of tiles (flattened over the
// images) and a 64 × 64 block of (output, summed) channels, and stores its partial ∂U_ξ; the
// ξ = (1, 1) workgroups of the first channel block also store ∂M's row sums, which are the
// bias gradient's (that ∂M entry is the sum of the tile's four ∂Y). `winograd_weight_sum`
// adds every range's partials in a fixed order and transforms back.
//
// Here `outputs` is the layer's output channels (M), `summed` its input channels (C); the
// input is the layer's input maps (in_t), `v_out` its output's gradient, both local to the
// pass's images.

@group(0) @binding(1) var<storage, read> input: array<in_t>;
@group(0) @binding(2) var<storage, read> v_out: array<f32>;
// [ξ][part][m][c], then [part][m] for the bias.
@group(0) @binding(3) var<storage, read_write> partials: array<f32>;
@group(0) @binding(4) var<storage, read_write> v_params: array<f32>;

const WG: u32 = 256u;
// Output × summed channels per workgroup, tiles per staged slice.
const BM: u32 = 64u;
const BC: u32 = 64u;
const BK: u32 = 16u;
// Staged rows' stride in vec4s: one more than a row holds, because neighbouring invocations
// stage neighbouring tiles (rows): unpadded, their stores would all hit one bank of workgroup
// memory; padded they spread over the banks.
const ROW_A: u32 = BM / 4u + 1u;
const ROW_B: u32 = BC / 4u + 1u;
// ξ = (1, 1): Aᵀ's second column is (1, 1), so ∂M there sums a tile's four output gradients.
const BIAS_XI: u32 = 5u;

var<workgroup> tile_a: array<vec4<f32>, BK * ROW_A>;
var<workgroup> tile_b: array<vec4<f32>, BK * ROW_B>;

// The 4 output pixels entry ξ = (i, j) of A ∂Y Aᵀ sums for one tile (ai = at_col(i),
// aj = at_col(j)), as Taps: pixels past the map's edge get sign 0.
fn output_taps(tile: vec2<u32>, ai: vec2<f32>, aj: vec2<f32>) -> Taps {
    let y = 2u * tile.x;
    let x = 2u * tile.y;
    let right = x + 1u < wn.width;
    let below = y + 1u < wn.height;
    let inside = vec4<bool>(true, right, below, right & below);
    let at = vec4<u32>(y * wn.width + x, y * wn.width + x + 1u, (y + 1u) * wn.width + x,
        (y + 1u) * wn.width + x + 1u);
    let signs = vec4<f32>(ai.x * aj.x, ai.x * aj.y, ai.y * aj.x, ai.y * aj.y);
    return Taps(select(vec4<u32>(0u), at, inside), select(vec4<f32>(0.0), signs, inside));
}

// (image, tile row, tile column) of tile q of the flattened range.
fn tile_of(q: u32) -> vec3<u32> {
    let per_image = wn.tiles_x * wn.tiles_y;
    let t = q % per_image;
    return vec3<u32>(q / per_image, t / wn.tiles_x, t % wn.tiles_x);
}

fn bias_slot(part: u32, m: u32) -> u32 {
    return 16u * wn.parts * wn.outputs * wn.summed + part * wn.outputs + m;
}

@compute @workgroup_size(WG)
fn winograd_weight_part(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    // Grid: x the 16 positions, y the ranges of tiles, z channel blocks (output-major).
    let xi = wg.x;
    let part = wg.y;
    let c_blocks = (wn.summed + BC - 1u) / BC;
    let m0 = (wg.z / c_blocks) * BM;
    let c0 = (wg.z % c_blocks) * BC;
    let ri = bt_row(xi / 4u);
    let rj = bt_row(xi % 4u);
    let ai = at_col(xi / 4u);
    let aj = at_col(xi % 4u);
    let q_begin = part * wn.range;
    let q_end = min(wn.images * wn.tiles_x * wn.tiles_y, q_begin + wn.range);
    let with_bias = xi == BIAS_XI && c0 == 0u;
    // Thread: output channels m0 + 4·ty + r, summed channels c0 + 4·tx …
    let ty = lid / 16u;
    let tx = lid % 16u;
    var acc0 = vec4<f32>(0.0);
    var acc1 = vec4<f32>(0.0);
    var acc2 = vec4<f32>(0.0);
    var acc3 = vec4<f32>(0.0);
    var bias = vec4<f32>(0.0);
    // The tile this invocation stages in every slice is its kk (WG is a multiple of BK).
    let kk = lid % BK;
    let plane = wn.height * wn.width;
    for (var q0 = q_begin; q0 < q_end; q0 += BK) {
        let staged = q0 + kk < q_end;
        let t = tile_of(min(q0 + kk, q_end - 1u));
        let grad_taps = output_taps(t.yz, ai, aj);
        let taps = taps_of(t.yz, ri, rj);
        // Neighbouring invocations take neighbouring tiles: their reads are 2 pixels apart.
        for (var e = lid; e < BK * BM; e += WG) {
            let mm = e / BK;
            var va = 0.0;
            if staged && m0 + mm < wn.outputs {
                let base = (t.x * wn.outputs + m0 + mm) * plane;
                let o = grad_taps.offsets;
                let g = vec4<f32>(v_out[base + o.x], v_out[base + o.y], v_out[base + o.z],
                    v_out[base + o.w]);
                va = dot(grad_taps.signs, g);
            }
            tile_a[kk * ROW_A + mm / 4u][mm % 4u] = va;
        }
        for (var e = lid; e < BK * BC; e += WG) {
            let cc = e / BK;
            var vb = 0.0;
            if staged && c0 + cc < wn.summed {
                vb = transformed_input(t.x, c0 + cc, taps);
            }
            tile_b[kk * ROW_B + cc / 4u][cc % 4u] = vb;
        }
        workgroupBarrier();
        for (var k = 0u; k < BK; k++) {
            let a = tile_a[k * ROW_A + ty];
            let bv = tile_b[k * ROW_B + tx];
            acc0 += a.x * bv;
            acc1 += a.y * bv;
            acc2 += a.z * bv;
            acc3 += a.w * bv;
        }
        // Only the bias's workgroups sum ∂M's rows: kept out of every other product's loop.
        if with_bias {
            for (var k = 0u; k < BK; k++) {
                bias += tile_a[k * ROW_A + ty];
            }
        }
        workgroupBarrier();
    }
    let slot = (xi * wn.parts + part) * wn.outputs;
    var rows = array<vec4<f32>, 4>(acc0, acc1, acc2, acc3);
    for (var r = 0u; r < 4u; r++) {
        let m = m0 + 4u * ty + r;
        if m >= wn.outputs {
            continue;
        }
        for (var j = 0u; j < 4u; j++) {
            let c = c0 + 4u * tx + j;
            if c < wn.summed {
                partials[(slot + m) * wn.summed + c] = rows[r][j];
            }
        }
        if with_bias && tx == 0u {
            partials[bias_slot(part, m)] = bias[r];
        }
    }
}

// A workgroup per 16 (output, summed) channel pairs (consecutive summed channels, so a
// subgroup's loads of one range are contiguous): one invocation per pair and position sums
// that position's ranges in range order, then one per pair and weight forms ∂g = Gᵀ ∂U G into
// the layer's W[m][c][ky][kx]; the pairs of summed channel 0 also write the bias gradient.
// One invocation per pair summing all 16 positions left the sums a chain of 16 × ranges
// dependent loads in 4096 invocations, 0.65 ms on an H200. SUM_PAIRS (16, so that 16 pairs ×
// 16 positions fill the 256 invocations) is prepended by conv_winograd.rs.
var<workgroup> sums: array<f32, 16u * SUM_PAIRS>;

@compute @workgroup_size(256)
fn winograd_weight_sum(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    // dispatch_1d folds a long grid into y.
    let first = (wg.y * nwg.x + wg.x) * SUM_PAIRS;
    let pairs = wn.outputs * wn.summed;
    let xi = lid / SUM_PAIRS;
    let t = first + lid % SUM_PAIRS;
    if t < pairs {
        var s = 0.0;
        for (var part = 0u; part < wn.parts; part++) {
            s += partials[(xi * wn.parts + part) * pairs + t];
        }
        sums[lid] = s;
    }
    workgroupBarrier();
    // Invocation (weight, pair): ∂g[ky][kx] = Σ_ij G[i][ky]·G[j][kx]·∂U[i][j].
    let w = lid / SUM_PAIRS;
    let q = first + lid % SUM_PAIRS;
    if w < 9u && q < pairs {
        let ky = w / 3u;
        let kx = w % 3u;
        var g = 0.0;
        for (var i = 0u; i < 4u; i++) {
            var row = 0.0;
            for (var j = 0u; j < 4u; j++) {
                row += sums[(4u * i + j) * SUM_PAIRS + lid % SUM_PAIRS] * g_row(j)[kx];
            }
            g += g_row(i)[ky] * row;
        }
        v_params[wn.w_off + q * 9u + w] = g;
    }
    let m = q / wn.summed;
    if w == 9u && q < pairs && q % wn.summed == 0u && wn.bias_off != 0xffffffffu {
        var s = 0.0;
        for (var part = 0u; part < wn.parts; part++) {
            s += partials[bias_slot(part, m)];
        }
        v_params[wn.bias_off + m] = s;
    }
}
