// What conv_winograd.wgsl and conv_winograd_grad.wgsl share: the pass's uniform, the
// transforms' matrices and the transformed input. Each module declares `input`, the pass's
// input maps [image][channel][y][x] of in_t.

struct Wino {
    width: u32,
    height: u32,
    // Output channels (M) and summed channels (C) of this pass.
    outputs: u32,
    summed: u32,
    w_off: u32,
    // 0xffffffff: none.
    bias_off: u32,
    // 1: the input gradient (weights read as W[c][m] flipped, no bias).
    transposed: u32,
    // The first image's index in the input (MapSize::image0).
    image0: u32,
    tiles_x: u32,
    tiles_y: u32,
    // The weight gradient's: images, parts of the tiles summed apart, tiles per part.
    images: u32,
    parts: u32,
    range: u32,
    pad0: u32,
}

@group(0) @binding(0) var<uniform> wn: Wino;

// G·(r0, r1, r2) with G = [1 0 0; ½ ½ ½; ½ −½ ½; 0 0 1].
fn g_times(r: vec3<f32>) -> vec4<f32> {
    return vec4<f32>(r.x, 0.5 * (r.x + r.y + r.z), 0.5 * (r.x - r.y + r.z), r.z);
}

// Row i of G.
fn g_row(i: u32) -> vec3<f32> {
    switch i {
        case 0u: { return vec3<f32>(1.0, 0.0, 0.0); }
        case 1u: { return vec3<f32>(0.5, 0.5, 0.5); }
        case 2u: { return vec3<f32>(0.5, -0.5, 0.5); }
        default: { return vec3<f32>(0.0, 0.0, 1.0); }
    }
}

// Row i of Bᵀ = [1 0 −1 0; 0 1 1 0; 0 −1 1 0; 0 1 0 −1] as (first column, its sign, second
// column, its sign): every row has two entries.
fn bt_row(i: u32) -> vec4<i32> {
    switch i {
        case 0u: { return vec4<i32>(0, 1, 2, -1); }
        case 1u: { return vec4<i32>(1, 1, 2, 1); }
        case 2u: { return vec4<i32>(1, -1, 2, 1); }
        default: { return vec4<i32>(1, 1, 3, -1); }
    }
}

// Rows of Aᵀ = [1 1 1 0; 0 1 −1 −1], entry i of each.
fn at_col(i: u32) -> vec2<f32> {
    switch i {
        case 0u: { return vec2<f32>(1.0, 0.0); }
        case 1u: { return vec2<f32>(1.0, 1.0); }
        case 2u: { return vec2<f32>(1.0, -1.0); }
        default: { return vec2<f32>(0.0, -1.0); }
    }
}

// The 4 patch values entry ξ = (i, j) of Bᵀ d B sums for one tile, as offsets in a channel's
// plane and their signs (ri = bt_row(i), rj = bt_row(j)); a value outside the map (zero
// padding) has sign 0 and offset 0. Found once per tile and ξ, it serves every channel.
struct Taps {
    offsets: vec4<u32>,
    signs: vec4<f32>,
}

fn taps_of(tile: vec2<u32>, ri: vec4<i32>, rj: vec4<i32>) -> Taps {
    // The patch's top-left corner: the tile's first output moved by −pad.
    let rows = vec2<i32>(i32(2u * tile.x) - 1) + vec2<i32>(ri.x, ri.z);
    let cols = vec2<i32>(i32(2u * tile.y) - 1) + vec2<i32>(rj.x, rj.z);
    let row_in = rows >= vec2<i32>(0) & rows < vec2<i32>(i32(wn.height));
    let col_in = cols >= vec2<i32>(0) & cols < vec2<i32>(i32(wn.width));
    let inside = vec4<bool>(row_in.x & col_in.x, row_in.x & col_in.y, row_in.y & col_in.x,
        row_in.y & col_in.y);
    let w = i32(wn.width);
    let at = vec4<i32>(rows.x * w + cols.x, rows.x * w + cols.y, rows.y * w + cols.x,
        rows.y * w + cols.y);
    let signs = vec4<f32>(f32(ri.y * rj.y), f32(ri.y * rj.w), f32(ri.w * rj.y), f32(ri.w * rj.w));
    return Taps(select(vec4<u32>(0u), vec4<u32>(at), inside), select(vec4<f32>(0.0), signs, inside));
}

// Entry ξ of Bᵀ d B for channel c of image b, for the tile and ξ of `taps`.
fn transformed_input(b: u32, c: u32, taps: Taps) -> f32 {
    let base = ((b + wn.image0) * wn.summed + c) * wn.height * wn.width;
    let d = vec4<f32>(f32(input[base + taps.offsets.x]), f32(input[base + taps.offsets.y]),
        f32(input[base + taps.offsets.z]), f32(input[base + taps.offsets.w]));
    return dot(taps.signs, d);
}
