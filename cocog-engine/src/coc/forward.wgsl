// h_θ forward and the expansion, one thread per base Gaussian. Each layer's weights pass
// through workgroup memory in 64-output × 32-input tiles, so 64 Gaussians share every load.

@group(0) @binding(0) var<uniform> step: Step;
@group(0) @binding(1) var<storage, read> weights: array<f32>;
@group(0) @binding(2) var<storage, read> means: array<f32>;
@group(0) @binding(3) var<storage, read> log_scales: array<f32>;
@group(0) @binding(4) var<storage, read> quats: array<f32>;
@group(0) @binding(5) var<storage, read> focus: array<f32>;
// Per Gaussian, ACT_STRIDE floats: [input | a1 | a2 | a3 | heads], what the backward replays.
@group(0) @binding(6) var<storage, read_write> acts: array<f32>;
// The M + 1 sets, [set][base].
@group(0) @binding(7) var<storage, read_write> set_means: array<f32>;
@group(0) @binding(8) var<storage, read_write> set_log_scales: array<f32>;
@group(0) @binding(9) var<storage, read_write> set_quats: array<f32>;
// Per Gaussian: the gate c and ∂c/∂focus[view].
@group(0) @binding(10) var<storage, read_write> gates: array<f32>;

const TILE_OUT: u32 = 64u;
const TILE_IN: u32 = 32u;
var<workgroup> tile: array<f32, 2048>;

// dst = W·src + b (ReLU'd for trunk layers). Every thread of the workgroup calls it with the
// same l, so the barriers are uniform.
fn dense(l: u32, src: ptr<function, array<f32, MAXD>>, dst: ptr<function, array<f32, MAXD>>, lid: u32) {
    let d = layer_dims(l);
    for (var j = 0u; j < d.y; j++) {
        (*dst)[j] = weights[d.w + j];
    }
    for (var o0 = 0u; o0 < d.y; o0 += TILE_OUT) {
        for (var i0 = 0u; i0 < d.x; i0 += TILE_IN) {
            workgroupBarrier();
            for (var t = lid; t < TILE_OUT * TILE_IN; t += 64u) {
                let o = o0 + t / TILE_IN;
                let i = i0 + t % TILE_IN;
                var w = 0.0;
                if o < d.y && i < d.x {
                    w = weights[d.z + o * d.x + i];
                }
                tile[t] = w;
            }
            workgroupBarrier();
            let no = min(TILE_OUT, d.y - o0);
            let ni = min(TILE_IN, d.x - i0);
            for (var o = 0u; o < no; o++) {
                var s = 0.0;
                for (var i = 0u; i < ni; i++) {
                    s += tile[o * TILE_IN + i] * (*src)[i0 + i];
                }
                (*dst)[o0 + o] += s;
            }
        }
    }
    if l < 3u {
        for (var j = 0u; j < d.y; j++) {
            (*dst)[j] = max((*dst)[j], 0.0);
        }
    }
}

fn embed(x: vec3<f32>, freqs: u32, at: u32, out: ptr<function, array<f32, MAXD>>) -> u32 {
    var k = at;
    (*out)[k] = x.x; (*out)[k + 1u] = x.y; (*out)[k + 2u] = x.z;
    k += 3u;
    for (var f = 0u; f < freqs; f++) {
        let s = x * f32(1u << f);
        let sn = sin(s);
        let cs = cos(s);
        (*out)[k] = sn.x; (*out)[k + 1u] = sn.y; (*out)[k + 2u] = sn.z;
        (*out)[k + 3u] = cs.x; (*out)[k + 4u] = cs.y; (*out)[k + 5u] = cs.z;
        k += 6u;
    }
    return k;
}

fn store(row: u32, at: u32, len: u32, v: ptr<function, array<f32, MAXD>>) {
    for (var j = 0u; j < len; j++) {
        acts[row + at + j] = (*v)[j];
    }
}

@compute @workgroup_size(64)
fn forward(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let n = linear_id(wg, nwg, lid, 64u);
    let live = n < step.n;
    // Threads past the end compute on the last Gaussian (their barriers still count) and
    // write nothing.
    let g = min(n, step.n - 1u);
    let mean = vec3<f32>(means[3u * g], means[3u * g + 1u], means[3u * g + 2u]);
    let ls = vec3<f32>(log_scales[3u * g], log_scales[3u * g + 1u], log_scales[3u * g + 2u]);
    let q = vec4<f32>(quats[4u * g], quats[4u * g + 1u], quats[4u * g + 2u], quats[4u * g + 3u]);
    let unit = q / length(q);

    var a: array<f32, MAXD>;
    var b: array<f32, MAXD>;
    var k = embed(mean, MEAN_FREQS, 0u, &a);
    k = embed(step.centre, CAMERA_FREQS, k, &a);
    let s = exp(ls);
    a[k] = s.x; a[k + 1u] = s.y; a[k + 2u] = s.z;
    a[k + 3u] = unit.x; a[k + 4u] = unit.y; a[k + 5u] = unit.z; a[k + 6u] = unit.w;

    let row = g * ACT_STRIDE;
    if live { store(row, 0u, IN_DIM, &a); }
    dense(0u, &a, &b, lid);
    if live { store(row, act_offset(1u), WIDTH, &b); }
    dense(1u, &b, &a, lid);
    if live { store(row, act_offset(2u), WIDTH, &a); }
    dense(2u, &a, &b, lid);
    if live { store(row, act_offset(3u), WIDTH, &b); }
    dense(3u, &b, &a, lid);
    if !live {
        return;
    }
    store(row, act_offset(4u), HEADS, &a);

    let dist = length(mean - step.centre);
    let focus_distance = focus[step.view] * step.focus_scale;
    let diff = 1.0 / dist - 1.0 / focus_distance;
    let c = abs(diff);
    gates[2u * g] = c;
    gates[2u * g + 1u] = sign(diff) / (focus_distance * focus_distance) * step.focus_scale;

    for (var m = 0u; m <= M; m++) {
        var shift = vec3<f32>(0.0);
        if m < M {
            let raw = vec3<f32>(a[H_POS + 3u * m], a[H_POS + 3u * m + 1u], a[H_POS + 3u * m + 2u]);
            if PAPER {
                let aperture = softplus(a[H_APERTURE]);
                let beta = sigmoid(a[H_BETA + m]);
                shift = 0.5 * aperture * c * beta * raw / max(length(raw), 1e-12);
            } else {
                shift = c * raw;
            }
        }
        let o = m * step.n + g;
        let p = mean + shift;
        set_means[3u * o] = p.x; set_means[3u * o + 1u] = p.y; set_means[3u * o + 2u] = p.z;
        for (var j = 0u; j < 3u; j++) {
            set_log_scales[3u * o + j] = ls[j] + log(multiplier(c, a[H_SCALE + 3u * m + j]).x);
        }
        for (var j = 0u; j < 4u; j++) {
            set_quats[4u * o + j] = unit[j] * multiplier(c, a[H_ROT + 4u * m + j]).x;
        }
    }
}
