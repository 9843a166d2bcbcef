// Zero-padded stride-1 convolutions, one thread per output value: the forward and the weight
// and bias gradients (each weight sums over every pixel of every image, in a fixed order).
// F's one-channel head runs here; its wider layers run as implicit GEMMs (conv_gemm.rs). Maps are [image][channel][y][x]; the first layer
// reads the renders' rgba [image][y][x][4] directly.

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
    // 1 when the input is the renders' rgba layout.
    rgba_input: u32,
    pad0: u32,
    pad1: u32,
    pad2: u32,
}

@group(0) @binding(0) var<uniform> cv: Conv;
@group(0) @binding(1) var<storage, read> params: array<f32>;
@group(0) @binding(2) var<storage, read> input: array<f32>;
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
    let p = (i * cv.height + u32(y)) * cv.width + u32(x);
    if cv.rgba_input == 1u {
        return input[p * 4u + c];
    }
    return input[((i * cv.cin + c) * cv.height + u32(y)) * cv.width + u32(x)];
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
    output[t] = s;
}

// One thread per weight (then one per bias): Σ over images and pixels.
@compute @workgroup_size(256)
fn conv_weight_grad(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let t = index(wg, nwg, lid);
    let kk = cv.k * cv.k;
    let weights = cv.cout * cv.cin * kk;
    var biases = 0u;
    if cv.bias_off != NO_BIAS {
        biases = cv.cout;
    }
    if t >= weights + biases {
        return;
    }
    let pad = i32(cv.k / 2u);
    var s = 0.0;
    if t >= weights {
        let co = t - weights;
        for (var i = 0u; i < cv.images; i++) {
            let base = (i * cv.cout + co) * cv.height * cv.width;
            for (var p = 0u; p < cv.height * cv.width; p++) {
                s += v_out[base + p];
            }
        }
        v_params[cv.bias_off + co] = s;
        return;
    }
    let kx = i32(t % cv.k);
    let ky = i32((t / cv.k) % cv.k);
    let ci = (t / kk) % cv.cin;
    let co = t / (kk * cv.cin);
    for (var i = 0u; i < cv.images; i++) {
        let base = (i * cv.cout + co) * cv.height * cv.width;
        for (var y = 0u; y < cv.height; y++) {
            for (var x = 0u; x < cv.width; x++) {
                let v = read_input(i, ci, i32(y) + ky - pad, i32(x) + kx - pad);
                s += v_out[base + y * cv.width + x] * v;
            }
        }
    }
    v_params[cv.w_off + t] = s;
}
