// Zero-padded stride-1 convolutions for F's one-channel head (its wider layers run as implicit
// GEMMs, conv_gemm.rs): the forward, one thread per output value, and the weight and bias
// gradients, each a sum over every pixel of every image. That sum is split into ranges of
// pixels, one thread per (weight, range), then each weight's partial sums are added by one
// workgroup in a fixed order: a thread per weight walking all pixels would leave a GPU with a
// few hundred threads, each a long chain of dependent loads. Maps are [image][channel][y][x];
// the input is a stored map (map_t, the prelude's).
// The uniform `cv`, `partials` and `ranges_total` are conv_common.wgsl's, prepended.

@group(0) @binding(1) var<storage, read> params: array<f32>;
@group(0) @binding(2) var<storage, read> input: array<map_t>;
@group(0) @binding(3) var<storage, read_write> output: array<f32>;
@group(0) @binding(4) var<storage, read> v_out: array<f32>;
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

@compute @workgroup_size(256)
fn conv_forward(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let t = index(wg, nwg, lid);
    let hw = cv.height * cv.width;
    if t >= cv.images * cv.cout * hw {
        return;
    }
    let x = t % cv.width;
    let y = (t / cv.width) % cv.height;
    let co = (t / hw) % cv.cout;
    let i = t / (hw * cv.cout);
    let pad = i32(cv.k / 2u);
    var s = 0.0;
    if cv.bias_off != NO_BIAS {
        s = params[cv.bias_off + co];
    }
    for (var ci = 0u; ci < cv.cin; ci++) {
        let w0 = cv.w_off + (co * cv.cin + ci) * cv.k * cv.k;
        for (var ky = 0u; ky < cv.k; ky++) {
            for (var kx = 0u; kx < cv.k; kx++) {
                let v = read_input(i, ci, i32(y + ky) - pad, i32(x + kx) - pad);
                s += params[w0 + ky * cv.k + kx] * v;
            }
        }
    }
    output[t + cv.image0 * cv.cout * hw] = s;
}

fn weight_count() -> u32 {
    var biases = 0u;
    if cv.bias_off != NO_BIAS {
        biases = cv.cout;
    }
    return cv.cout * cv.cin * cv.k * cv.k + biases;
}

// Thread x: weight (then bias) t, over the positions of range wg.y.
@compute @workgroup_size(64)
fn conv_weight_grad_part(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let t = wg.x * 64u + lid;
    let count = weight_count();
    if t >= count {
        return;
    }
    let hw = cv.height * cv.width;
    let begin = wg.y * cv.per_part;
    let end = min(begin + cv.per_part, cv.images * hw);
    let kk = cv.k * cv.k;
    let weights = cv.cout * cv.cin * kk;
    let bias = t >= weights;
    var co = t / (kk * cv.cin);
    if bias {
        co = t - weights;
    }
    let ci = (t / kk) % cv.cin;
    let pad = i32(cv.k / 2u);
    let ky = i32((t / cv.k) % cv.k) - pad;
    let kx = i32(t % cv.k) - pad;
    // The position's image and pixel, advanced without a division per step.
    var i = begin / hw;
    var p = begin % hw;
    var y = p / cv.width;
    var x = p % cv.width;
    var s = 0.0;
    for (var q = begin; q < end; q++) {
        var v = 1.0;
        if !bias {
            v = read_input(i, ci, i32(y) + ky, i32(x) + kx);
        }
        s += v_out[((i + cv.image0) * cv.cout + co) * hw + y * cv.width + x] * v;
        x += 1u;
        if x == cv.width {
            x = 0u;
            y += 1u;
            if y == cv.height {
                y = 0u;
                i += 1u;
            }
        }
    }
    partials[wg.y * count + t] = s;
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
