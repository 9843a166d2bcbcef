// Zero-padded stride-1 convolutions for F's one-channel head (its wider layers run as implicit
// GEMMs, conv_gemm.rs): the forward, one thread per output value, the input gradient, one per
// pixel, and the weight gradient, a sum
// over every pixel of every image. That sum is split into blocks of pixels (head_weight_grad_part),
// then each weight's partial sums are added by one workgroup in a fixed order: a thread per
// weight walking all pixels would leave a GPU with a few hundred threads, each a long chain of
// dependent loads. Maps are [image][channel][y][x]; the input is a stored map (map_t, the
// prelude's).
// The uniform `cv`, `partials` and `ranges_total` are conv_common.wgsl's, prepended.

@group(0) @binding(1) var<storage, read> params: array<f32>;
@group(0) @binding(2) var<storage, read> input: array<map_t>;
@group(0) @binding(3) var<storage, read_write> output: array<f32>;
@group(0) @binding(4) var<storage, read> v_out: array<f32>;
@group(0) @binding(5) var<storage, read_write> v_in: array<f32>;
@group(0) @binding(6) var<storage, read_write> v_params: array<f32>;

const NO_BIAS: u32 = 0xffffffffu;

fn index(wg: vec3<u32>, nwg: vec3<u32>, lid: u32) -> u32 {
    return (wg.y * nwg.x + wg.x) * 256u + lid;
}

fn read_input(i: u32, c: u32, y: i32, x: i32) -> f32 {
    if y < 0 || x < 0 || y >= i32(cv.height) || x >= i32(cv.width) {
        return 0.0;
    }
    return f32(input[((i * cv.cin + c) * cv.height + u32(y)) * cv.width + u32(x)]);
}

// A neighbour's offset in a plane, clamped into it, and 1 where it lies inside, 0 where the
// zero padding is: each channel's nine loads then need no bounds tests of their own.
struct Tap {
    offset: u32,
    inside: f32,
}

fn tap(y: i32, x: i32) -> Tap {
    let inside = y >= 0 && x >= 0 && y < i32(cv.height) && x < i32(cv.width);
    let yc = u32(clamp(y, 0, i32(cv.height) - 1));
    let xc = u32(clamp(x, 0, i32(cv.width) - 1));
    return Tap(yc * cv.width + xc, select(0.0, 1.0, inside));
}

// The head's (3×3, C → 1) forward, one invocation per logit: per channel, nine independent
// loads of its 3×3 window, each named (an array indexed in a loop may live in memory).
@compute @workgroup_size(256)
fn conv_forward(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let t = index(wg, nwg, lid);
    let hw = cv.height * cv.width;
    if t >= cv.images * hw {
        return;
    }
    let x = i32(t % cv.width);
    let y = i32((t / cv.width) % cv.height);
    let i = t / hw;
    let t00 = tap(y - 1, x - 1);
    let t01 = tap(y - 1, x);
    let t02 = tap(y - 1, x + 1);
    let t10 = tap(y, x - 1);
    let t11 = tap(y, x);
    let t12 = tap(y, x + 1);
    let t20 = tap(y + 1, x - 1);
    let t21 = tap(y + 1, x);
    let t22 = tap(y + 1, x + 1);
    var s = 0.0;
    if cv.bias_off != NO_BIAS {
        s = params[cv.bias_off];
    }
    for (var c = 0u; c < cv.cin; c++) {
        let plane = (i * cv.cin + c) * hw;
        let w = cv.w_off + c * 9u;
        s += params[w] * t00.inside * f32(input[plane + t00.offset]);
        s += params[w + 1u] * t01.inside * f32(input[plane + t01.offset]);
        s += params[w + 2u] * t02.inside * f32(input[plane + t02.offset]);
        s += params[w + 3u] * t10.inside * f32(input[plane + t10.offset]);
        s += params[w + 4u] * t11.inside * f32(input[plane + t11.offset]);
        s += params[w + 5u] * t12.inside * f32(input[plane + t12.offset]);
        s += params[w + 6u] * t20.inside * f32(input[plane + t20.offset]);
        s += params[w + 7u] * t21.inside * f32(input[plane + t21.offset]);
        s += params[w + 8u] * t22.inside * f32(input[plane + t22.offset]);
    }
    output[t + cv.image0 * hw] = s;
}

// Logit gradient of image `base` (its first value) at (y, x), 0 in the padding.
fn logit_grad(base: u32, y: i32, x: i32) -> f32 {
    let at = tap(y, x);
    return at.inside * v_out[base + at.offset];
}

// The head's input gradient, ∂in[c](y, x) = Σ W[c][ky][kx] · ∂logit(y + 1 − ky, x + 1 − kx):
// one invocation per pixel loads its nine logit gradients once, then writes every channel's
// (neighbouring invocations on neighbouring addresses). As a GEMM it was a product nine deep.
// The taps are summed in the GEMM's order: in gpu_learned_mode_past_one_channel_block a
// first-layer weight gradient of 8e-5, two instance norms below, sat at the edge of its f32
// budget, and three partial sums of three tipped it over (4e-7 against 1.1e-7).
@compute @workgroup_size(256)
fn head_input_grad(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let t = index(wg, nwg, lid);
    let hw = cv.height * cv.width;
    if t >= cv.images * hw {
        return;
    }
    let p = t % hw;
    let x = i32(p % cv.width);
    let y = i32(p / cv.width);
    let i = t / hw;
    let base = (i + cv.image0) * hw;
    let g00 = logit_grad(base, y + 1, x + 1);
    let g01 = logit_grad(base, y + 1, x);
    let g02 = logit_grad(base, y + 1, x - 1);
    let g10 = logit_grad(base, y, x + 1);
    let g11 = logit_grad(base, y, x);
    let g12 = logit_grad(base, y, x - 1);
    let g20 = logit_grad(base, y - 1, x + 1);
    let g21 = logit_grad(base, y - 1, x);
    let g22 = logit_grad(base, y - 1, x - 1);
    for (var c = 0u; c < cv.cin; c++) {
        let w = cv.w_off + c * 9u;
        var s = params[w] * g00;
        s += params[w + 1u] * g01;
        s += params[w + 2u] * g02;
        s += params[w + 3u] * g10;
        s += params[w + 4u] * g11;
        s += params[w + 5u] * g12;
        s += params[w + 6u] * g20;
        s += params[w + 7u] * g21;
        s += params[w + 8u] * g22;
        v_in[(i * cv.cin + c) * hw + p] = s;
    }
}

fn weight_count() -> u32 {
    var biases = 0u;
    if cv.bias_off != NO_BIAS {
        biases = cv.cout;
    }
    return cv.cout * cv.cin * cv.k * cv.k + biases;
}

// The head's (3×3, C → 1, no bias) weight gradient, ∂W[c][ky][kx] = Σ ∂logit(y, x) ·
// in[c](y + ky − 1, x + kx − 1), in parts: a workgroup per channel, image and block of
// HEAD_ROWS rows × 64 columns. An invocation walks its column down the block with the 3×3
// window of inputs around it in registers (three new loads a row, neighbouring invocations on
// neighbouring addresses) and nine running sums; the workgroup then adds its invocations' sums
// in a fixed-order tree into one partial per tap, partials[block][c·9 + tap]. One invocation
// per (weight, range) walking positions one by one instead paid two gathers, four bounds tests
// and its index arithmetic for every multiply-add. HEAD_ROWS is the host's (composite.rs).
var<workgroup> tap_sums: array<f32, 576>;

fn window_row(i: u32, c: u32, y: i32, x: i32) -> vec3<f32> {
    return vec3<f32>(read_input(i, c, y, x - 1), read_input(i, c, y, x), read_input(i, c, y, x + 1));
}

@compute @workgroup_size(64)
fn head_weight_grad_part(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    // Grid: x column blocks, y row blocks, z images × channels.
    let row_blocks = (cv.height + HEAD_ROWS - 1u) / HEAD_ROWS;
    let col_blocks = (cv.width + 63u) / 64u;
    let c = wg.z % cv.cin;
    let i = wg.z / cv.cin;
    let rb = wg.y;
    let x = wg.x * 64u + lid;
    let xi = i32(x);
    let y0 = rb * HEAD_ROWS;
    let y1 = min(y0 + HEAD_ROWS, cv.height);
    let hw = cv.height * cv.width;
    var a00 = 0.0;
    var a01 = 0.0;
    var a02 = 0.0;
    var a10 = 0.0;
    var a11 = 0.0;
    var a12 = 0.0;
    var a20 = 0.0;
    var a21 = 0.0;
    var a22 = 0.0;
    if x < cv.width {
        // Rows y − 1, y and y + 1 of the window, each at columns x − 1, x, x + 1.
        var top = window_row(i, c, i32(y0) - 1, xi);
        var mid = window_row(i, c, i32(y0), xi);
        let v_row = (i + cv.image0) * hw + x;
        for (var y = y0; y < y1; y++) {
            let bottom = window_row(i, c, i32(y) + 1, xi);
            let v = v_out[v_row + y * cv.width];
            a00 += v * top.x;
            a01 += v * top.y;
            a02 += v * top.z;
            a10 += v * mid.x;
            a11 += v * mid.y;
            a12 += v * mid.z;
            a20 += v * bottom.x;
            a21 += v * bottom.y;
            a22 += v * bottom.z;
            top = mid;
            mid = bottom;
        }
    }
    tap_sums[lid] = a00;
    tap_sums[64u + lid] = a01;
    tap_sums[128u + lid] = a02;
    tap_sums[192u + lid] = a10;
    tap_sums[256u + lid] = a11;
    tap_sums[320u + lid] = a12;
    tap_sums[384u + lid] = a20;
    tap_sums[448u + lid] = a21;
    tap_sums[512u + lid] = a22;
    for (var w = 32u; w > 0u; w >>= 1u) {
        workgroupBarrier();
        if lid < w {
            for (var tap = 0u; tap < 9u; tap++) {
                tap_sums[tap * 64u + lid] += tap_sums[tap * 64u + lid + w];
            }
        }
    }
    workgroupBarrier();
    if lid < 9u {
        let block = (i * row_blocks + rb) * col_blocks + wg.x;
        partials[block * weight_count() + c * 9u + lid] = tap_sums[lid * 64u];
    }
}

// One workgroup per weight: its ranges' partial sums, added in a fixed order.
@compute @workgroup_size(256)
fn conv_weight_grad_sum(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let t = wg.y * nwg.x + wg.x;
    let count = weight_count();
    if t >= count {
        return;
    }
    let total = ranges_total(lid, t, count);
    if lid == 0u {
        let weights = cv.cout * cv.cin * cv.k * cv.k;
        if t >= weights {
            v_params[cv.bias_off + t - weights] = total;
        } else {
            v_params[cv.w_off + t] = total;
        }
    }
}
