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

fn input_at(b: u32, c: u32, y: i32, x: i32) -> f32 {
    if y < 0 || x < 0 || y >= i32(wn.height) || x >= i32(wn.width) {
        return 0.0;
    }
    let plane = (b + wn.image0) * wn.summed + c;
    return f32(input[(plane * wn.height + u32(y)) * wn.width + u32(x)]);
}


// Entry ξ = (i, j) of Bᵀ d B for channel c of the tile at (row, column) `tile` of image b, where
// ri = bt_row(i), rj = bt_row(j) and d is the tile's 4×4 input patch (zero outside the map).
fn transformed_input(b: u32, c: u32, tile: vec2<u32>, ri: vec4<i32>, rj: vec4<i32>) -> f32 {
    // The patch's top-left corner: the tile's first output moved by −pad.
    let py = i32(2u * tile.x) - 1;
    let px = i32(2u * tile.y) - 1;
    let top = f32(rj.y) * input_at(b, c, py + ri.x, px + rj.x)
        + f32(rj.w) * input_at(b, c, py + ri.x, px + rj.z);
    let bottom = f32(rj.y) * input_at(b, c, py + ri.z, px + rj.x)
        + f32(rj.w) * input_at(b, c, py + ri.z, px + rj.z);
    return f32(ri.y) * top + f32(ri.w) * bottom;
}
