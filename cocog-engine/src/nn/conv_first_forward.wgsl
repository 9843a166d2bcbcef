// F's first layer's forward, a zero-padded 5×5 convolution from a render's rgb to C channels:
// z[b][co][p] = bias[co] + Σ_{ci,ky,kx} W[co][ci][ky][kx] · rgb[b][ci][p + (ky, kx) − 2].
// Renders are rgba [image][y][x][4] (f32); z is the chunk's own maps [image][channel][y][x].
// The uniform `cv` is conv_common.wgsl's, prepended, as is `map_t` (precision.rs).
//
// As an implicit GEMM every element of the im2col tile paid a division, a bounds test and a
// gather; here a workgroup stages its window (its block and a 2-pixel border) and 32
// channels' weights once, and each invocation keeps its pixel's 32 sums in named vec4s (a
// local array indexed in a loop may live in memory on NVIDIA).

@group(0) @binding(1) var<storage, read> params: array<f32>;
@group(0) @binding(2) var<storage, read> renders: array<f32>;
@group(0) @binding(3) var<storage, read_write> z: array<map_t>;

// A block of pixels per workgroup, 32 wide so that a subgroup writes a row of a plane.
const BW: u32 = 32u;
const BH: u32 = 4u;
const PW: u32 = 36u;
const PH: u32 = 8u;
// Inputs per pixel (3 channels × 25 taps, the weights' order) and output channels per
// workgroup, 4 per vec4.
const INPUTS: u32 = 75u;
const CHANNELS: u32 = 32u;

// [input][channel / 4]: the weights of the workgroup's 32 channels.
var<workgroup> w_stage: array<vec4<f32>, 600>;
// [channel][row][column] of the window, zero outside the render.
var<workgroup> window: array<f32, 864>;

@compute @workgroup_size(32, 4)
fn first_forward(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(local_invocation_id) l: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    // Grid: x and y blocks, z (image, block of 32 channels).
    let blocks = (cv.cout + CHANNELS - 1u) / CHANNELS;
    let b = wg.z / blocks;
    let co0 = (wg.z % blocks) * CHANNELS;
    let x0 = wg.x * BW;
    let y0 = wg.y * BH;
    let hw = cv.height * cv.width;
    // A channel's 75 weights are consecutive in `params`, so consecutive invocations read them.
    for (var e = lid; e < INPUTS * CHANNELS; e += BW * BH) {
        let c = e / INPUTS;
        let j = e % INPUTS;
        var v = 0.0;
        if co0 + c < cv.cout {
            v = params[cv.w_off + (co0 + c) * INPUTS + j];
        }
        w_stage[j * 8u + c / 4u][c % 4u] = v;
    }
    for (var e = lid; e < 3u * PH * PW; e += BW * BH) {
        let c = e / (PH * PW);
        let yy = i32(y0 + (e / PW) % PH) - 2;
        let xx = i32(x0 + e % PW) - 2;
        var v = 0.0;
        if yy >= 0 && xx >= 0 && yy < i32(cv.height) && xx < i32(cv.width) {
            v = renders[((b + cv.image0) * hw + u32(yy) * cv.width + u32(xx)) * 4u + c];
        }
        window[e] = v;
    }
    workgroupBarrier();

    var a0 = vec4<f32>(0.0);
    var a1 = vec4<f32>(0.0);
    var a2 = vec4<f32>(0.0);
    var a3 = vec4<f32>(0.0);
    var a4 = vec4<f32>(0.0);
    var a5 = vec4<f32>(0.0);
    var a6 = vec4<f32>(0.0);
    var a7 = vec4<f32>(0.0);
    for (var c = 0u; c < 3u; c++) {
        for (var ky = 0u; ky < 5u; ky++) {
            let row = (c * PH + l.y + ky) * PW + l.x;
            let j0 = (c * 5u + ky) * 5u;
            for (var kx = 0u; kx < 5u; kx++) {
                let v = window[row + kx];
                let w = (j0 + kx) * 8u;
                a0 += v * w_stage[w];
                a1 += v * w_stage[w + 1u];
                a2 += v * w_stage[w + 2u];
                a3 += v * w_stage[w + 3u];
                a4 += v * w_stage[w + 4u];
                a5 += v * w_stage[w + 5u];
                a6 += v * w_stage[w + 6u];
                a7 += v * w_stage[w + 7u];
            }
        }
    }
    let x = x0 + l.x;
    let y = y0 + l.y;
    if x >= cv.width || y >= cv.height {
        return;
    }
    let p = y * cv.width + x;
    store4(b, co0, p, a0);
    store4(b, co0 + 4u, p, a1);
    store4(b, co0 + 8u, p, a2);
    store4(b, co0 + 12u, p, a3);
    store4(b, co0 + 16u, p, a4);
    store4(b, co0 + 20u, p, a5);
    store4(b, co0 + 24u, p, a6);
    store4(b, co0 + 28u, p, a7);
}

// Channels co.. co + 3 (those that exist) of pixel p of local image b, with their biases.
fn store4(b: u32, co: u32, p: u32, v: vec4<f32>) {
    let hw = cv.height * cv.width;
    for (var r = 0u; r < 4u; r++) {
        if co + r < cv.cout {
            var bias = 0.0;
            if cv.bias_off != 0xffffffffu {
                bias = params[cv.bias_off + co + r];
            }
            z[(b * cv.cout + co + r) * hw + p] = to_map(v[r] + bias);
        }
    }
}
