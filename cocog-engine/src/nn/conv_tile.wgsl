// F's wide convolutions (stride 1, zero padding KS / 2) with spatial tiles: a workgroup computes
// 64 output channels × a block of 8 rows × 16 columns of one image. Per slice of CC summed
// channels it stages the block's input patch (with its KS − 1 halo) and the slice's weights in
// workgroup memory, so each input value is read from global memory once per slice instead of
// KS² times through an im2col gather, and no thread divides to find a tap. A thread keeps
// 4 channels × 8 neighbouring pixels of one row; per kernel row it reads 8 + KS − 1 patch
// values once and reuses them for every column of the kernel.
//
// The same kernel computes the input gradient of a convolution: the gradient is the
// convolution of the output gradient with the kernel transposed (in ↔ out) and flipped
// (TRANSPOSED). The prelude defines KS (3 or 5), CC, the element types in_t and out_t of the
// input and output (f32, or map_t for F's stored maps), and to_out, the output's conversion.
//
// Maps are [image][channel][y][x]; with rgba_input the input is the renders' [image][y][x][4].

struct ConvTile {
    width: u32,
    height: u32,
    // Output channels (M) and summed channels (C) of this pass.
    outputs: u32,
    summed: u32,
    w_off: u32,
    // 0xffffffff: none.
    bias_off: u32,
    rgba_input: u32,
    // 1: the input gradient (weights read as W[c][m] flipped, no bias).
    transposed: u32,
    // The first image's index in the input (MapSize::image0).
    image0: u32,
    pad0: u32,
    pad1: u32,
    pad2: u32,
}

@group(0) @binding(0) var<uniform> cv: ConvTile;
@group(0) @binding(1) var<storage, read> params: array<f32>;
@group(0) @binding(2) var<storage, read> input: array<in_t>;
@group(0) @binding(3) var<storage, read_write> output: array<out_t>;

const KK: u32 = KS * KS;
const PAD: i32 = i32(KS / 2u);
const TH: u32 = 8u;
const TW: u32 = 16u;
const PH: u32 = TH + KS - 1u;
const PW: u32 = TW + KS - 1u;
// Pixels per thread, along a row.
const RUN: u32 = 8u;

// [summed channel of the slice][tap][output channel / 4]
var<workgroup> w_s: array<vec4<f32>, CC * KK * 16u>;
// [summed channel of the slice][patch row][patch column]
var<workgroup> tile_in: array<f32, CC * PH * PW>;

fn weight(m: u32, c: u32, k: u32) -> f32 {
    if m >= cv.outputs || c >= cv.summed {
        return 0.0;
    }
    if cv.transposed == 1u {
        // The layer's weights are W[c][m][tap] with m its input channels.
        return params[cv.w_off + (c * cv.outputs + m) * KK + (KK - 1u - k)];
    }
    return params[cv.w_off + (m * cv.summed + c) * KK + k];
}

fn input_at(b: u32, c: u32, y: i32, x: i32) -> f32 {
    if c >= cv.summed || y < 0 || x < 0 || y >= i32(cv.height) || x >= i32(cv.width) {
        return 0.0;
    }
    let p = u32(y) * cv.width + u32(x);
    let i = b + cv.image0;
    if cv.rgba_input == 1u {
        return f32(input[(i * cv.height * cv.width + p) * 4u + c]);
    }
    return f32(input[(i * cv.summed + c) * cv.height * cv.width + p]);
}

@compute @workgroup_size(256)
fn conv_tile(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    // Grid: x column blocks, y row blocks × 64-channel blocks, z images.
    let tiles_y = (cv.height + TH - 1u) / TH;
    let x0 = wg.x * TW;
    let y0 = (wg.y % tiles_y) * TH;
    let m0 = (wg.y / tiles_y) * 64u;
    let b = wg.z;
    // Thread: output channels m0 + 4·ty …, pixels (y0 + row, x0 + col … col + 7).
    let ty = lid / 16u;
    let g = lid % 16u;
    let row = g / 2u;
    let col = (g % 2u) * RUN;
    var acc: array<vec4<f32>, RUN>;
    for (var j = 0u; j < RUN; j++) {
        acc[j] = vec4<f32>(0.0);
    }
    for (var c0 = 0u; c0 < cv.summed; c0 += CC) {
        for (var e = lid; e < CC * KK * 64u; e += 256u) {
            let m = e % 64u;
            let k = (e / 64u) % KK;
            let cl = e / (64u * KK);
            w_s[(cl * KK + k) * 16u + m / 4u][m % 4u] = weight(m0 + m, c0 + cl, k);
        }
        for (var e = lid; e < CC * PH * PW; e += 256u) {
            let px = e % PW;
            let py = (e / PW) % PH;
            let cl = e / (PW * PH);
            tile_in[e] = input_at(b, c0 + cl, i32(y0 + py) - PAD, i32(x0 + px) - PAD);
        }
        workgroupBarrier();
        for (var cl = 0u; cl < CC; cl++) {
            for (var ky = 0u; ky < KS; ky++) {
                var line: array<f32, RUN + KS - 1u>;
                let base = (cl * PH + row + ky) * PW + col;
                for (var j = 0u; j < RUN + KS - 1u; j++) {
                    line[j] = tile_in[base + j];
                }
                for (var kx = 0u; kx < KS; kx++) {
                    let a = w_s[(cl * KK + ky * KS + kx) * 16u + ty];
                    for (var j = 0u; j < RUN; j++) {
                        acc[j] += a * line[j + kx];
                    }
                }
            }
        }
        workgroupBarrier();
    }
    let y = y0 + row;
    if y >= cv.height {
        return;
    }
    for (var i = 0u; i < 4u; i++) {
        let m = m0 + 4u * ty + i;
        if m >= cv.outputs {
            continue;
        }
        var bias = 0.0;
        if cv.bias_off != 0xffffffffu && cv.transposed == 0u {
            bias = params[cv.bias_off + m];
        }
        let out_row = ((b * cv.outputs + m) * cv.height + y) * cv.width;
        for (var j = 0u; j < RUN; j++) {
            let x = x0 + col + j;
            if x < cv.width {
                output[out_row + x] = to_out(acc[j][i] + bias);
            }
        }
    }
}
