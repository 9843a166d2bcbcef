// F's one-channel head (its wider layers run as implicit GEMMs or by Winograd): a zero-padded
// stride-1 3×3 convolution from `cin` channels to one, with no bias. Its forward and input
// gradient take one invocation per pixel; its weight gradient sums over every pixel of every
// image in ranges of pixels, a workgroup per (input channel, range) whose invocations walk the
// range's pixels (so each load is coalesced) and add their nine sums in workgroup memory; then
// each weight's ranges are added by one workgroup in a fixed order. A pixel's nine taps, their
// offsets and edge tests are found once, outside the channel loops: found per tap and channel
// (the kernel size a uniform), they made these kernels instruction-bound on an H200 (1.7 ms at
// 400×300, for 1.7 GFLOP). Maps are [image][channel][y][x]; the input is a stored map (map_t,
// the prelude's).

struct Conv {
    images: u32,
    cin: u32,
    cout: u32,
    k: u32,
    height: u32,
    width: u32,
    // Offsets into the parameter buffer; bias_off = 0xffffffff for none.
    w_off: u32,
    bias_off: u32,
    pad: u32,
    // The weight gradient's split: (image, pixel) positions per range, and ranges.
    per_part: u32,
    parts: u32,
    // The chunk's first image in `output` (forward) and `v_out` (the gradients), which hold
    // every render's logits; `input` and `v_in` hold the chunk's maps alone.
    image0: u32,
}

@group(0) @binding(0) var<uniform> cv: Conv;
@group(0) @binding(1) var<storage, read> params: array<f32>;
@group(0) @binding(2) var<storage, read> input: array<map_t>;
@group(0) @binding(3) var<storage, read_write> output: array<f32>;
@group(0) @binding(4) var<storage, read> v_out: array<f32>;
@group(0) @binding(5) var<storage, read_write> v_in: array<f32>;
@group(0) @binding(6) var<storage, read_write> v_params: array<f32>;
// [range][weight].
@group(0) @binding(7) var<storage, read_write> partials: array<f32>;

const NO_BIAS: u32 = 0xffffffffu;
const TAPS: u32 = 9u;

fn index(wg: vec3<u32>, nwg: vec3<u32>, lid: u32) -> u32 {
    return (wg.y * nwg.x + wg.x) * 256u + lid;
}

// Offsets within a plane of pixel (y, x) moved by sign · ((ky, kx) − 1) for each tap, −1
// where that falls outside the map.
fn tap_offsets(y: u32, x: u32, sign: i32) -> array<i32, 9> {
    var o: array<i32, 9>;
    for (var ky = 0; ky < 3; ky++) {
        for (var kx = 0; kx < 3; kx++) {
            let yy = i32(y) + sign * (ky - 1);
            let xx = i32(x) + sign * (kx - 1);
            let inside = yy >= 0 && xx >= 0 && yy < i32(cv.height) && xx < i32(cv.width);
            o[ky * 3 + kx] = select(-1, yy * i32(cv.width) + xx, inside);
        }
    }
    return o;
}

// The logit of pixel t of the chunk's images.
@compute @workgroup_size(256)
fn conv_forward(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let t = index(wg, nwg, lid);
    let hw = cv.height * cv.width;
    if t >= cv.images * hw {
        return;
    }
    let p = t % hw;
    let i = t / hw;
    let o = tap_offsets(p / cv.width, p % cv.width, 1);
    var s = 0.0;
    for (var ci = 0u; ci < cv.cin; ci++) {
        let base = (i * cv.cin + ci) * hw;
        let w0 = cv.w_off + ci * TAPS;
        for (var tap = 0u; tap < TAPS; tap++) {
            if o[tap] >= 0 {
                s += params[w0 + tap] * f32(input[base + u32(o[tap])]);
            }
        }
    }
    output[t + cv.image0 * hw] = s;
}

// v_in[i][ci][p] = Σ_tap W[ci][tap] · v_out[i][p − tap + 1], one invocation per pixel.
@compute @workgroup_size(256)
fn conv_input_grad(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let t = index(wg, nwg, lid);
    let hw = cv.height * cv.width;
    if t >= cv.images * hw {
        return;
    }
    let p = t % hw;
    let i = t / hw;
    let o = tap_offsets(p / cv.width, p % cv.width, -1);
    let out0 = (i + cv.image0) * hw;
    var g: array<f32, 9>;
    for (var tap = 0u; tap < TAPS; tap++) {
        g[tap] = 0.0;
        if o[tap] >= 0 {
            g[tap] = v_out[out0 + u32(o[tap])];
        }
    }
    for (var ci = 0u; ci < cv.cin; ci++) {
        let w0 = cv.w_off + ci * TAPS;
        var s = 0.0;
        for (var tap = 0u; tap < TAPS; tap++) {
            s += params[w0 + tap] * g[tap];
        }
        v_in[(i * cv.cin + ci) * hw + p] = s;
    }
}

// Per tap, then invocation: the workgroup's nine sums while they are added up.
var<workgroup> tap_sums: array<f32, 2304>;

// Workgroup (ci, range): ∂W[ci][tap] over the range's positions, into partials.
@compute @workgroup_size(256)
fn conv_weight_grad_part(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let ci = wg.x;
    let hw = cv.height * cv.width;
    let begin = wg.y * cv.per_part;
    let end = min(begin + cv.per_part, cv.images * hw);
    var acc: array<f32, 9>;
    for (var tap = 0u; tap < TAPS; tap++) {
        acc[tap] = 0.0;
    }
    for (var q = begin + lid; q < end; q += 256u) {
        let p = q % hw;
        let i = q / hw;
        let g = v_out[(i + cv.image0) * hw + p];
        let o = tap_offsets(p / cv.width, p % cv.width, 1);
        let base = (i * cv.cin + ci) * hw;
        for (var tap = 0u; tap < TAPS; tap++) {
            if o[tap] >= 0 {
                acc[tap] += g * f32(input[base + u32(o[tap])]);
            }
        }
    }
    for (var tap = 0u; tap < TAPS; tap++) {
        tap_sums[tap * 256u + lid] = acc[tap];
    }
    for (var w = 128u; w > 0u; w >>= 1u) {
        workgroupBarrier();
        if lid < w {
            for (var tap = 0u; tap < TAPS; tap++) {
                tap_sums[tap * 256u + lid] += tap_sums[tap * 256u + lid + w];
            }
        }
    }
    workgroupBarrier();
    if lid < TAPS {
        partials[wg.y * cv.cin * TAPS + ci * TAPS + lid] = tap_sums[lid * 256u];
    }
}

fn weight_count() -> u32 {
    return cv.cin * TAPS;
}

var<workgroup> sums: array<f32, 256>;

// One workgroup per weight: its ranges' partial sums, added in a fixed order.
@compute @workgroup_size(256)
fn conv_weight_grad_sum(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let t = wg.y * nwg.x + wg.x;
    let count = weight_count();
    if t >= count {
        return;
    }
    var s = 0.0;
    for (var r = lid; r < cv.parts; r += 256u) {
        s += partials[r * count + t];
    }
    sums[lid] = s;
    for (var w = 128u; w > 0u; w >>= 1u) {
        workgroupBarrier();
        if lid < w {
            sums[lid] += sums[lid + w];
        }
    }
    if lid == 0u {
        v_params[cv.w_off + t] = sums[0];
    }
}
