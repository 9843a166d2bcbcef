// The adjoint of the expansion and of h_θ, one thread per base Gaussian: sums the M + 1 sets'
// gradients into the base, then runs the heads' gradient back through the trunk, keeping each
// layer's output gradient for the weight-gradient pass (the input is detached: it stops there).

@group(0) @binding(0) var<uniform> step: Step;
@group(0) @binding(1) var<storage, read> weights: array<f32>;
@group(0) @binding(2) var<storage, read> quats: array<f32>;
@group(0) @binding(3) var<storage, read> acts: array<f32>;
@group(0) @binding(4) var<storage, read> gates: array<f32>;
@group(0) @binding(5) var<storage, read> v_set_means: array<f32>;
@group(0) @binding(6) var<storage, read> v_set_log_scales: array<f32>;
@group(0) @binding(7) var<storage, read> v_set_quats: array<f32>;
@group(0) @binding(8) var<storage, read_write> v_means: array<f32>;
@group(0) @binding(9) var<storage, read_write> v_log_scales: array<f32>;
@group(0) @binding(10) var<storage, read_write> v_quats: array<f32>;
// Per Gaussian, DELTA_STRIDE floats: the gradients of [a1 | a2 | a3 | heads] (pre-activation).
@group(0) @binding(11) var<storage, read_write> deltas: array<f32>;
// Per Gaussian, its share of ∂loss/∂focus[view].
@group(0) @binding(12) var<storage, read_write> focus_terms: array<f32>;

const TILE_OUT: u32 = 32u;
const TILE_IN: u32 = 64u;
var<workgroup> tile: array<f32, 2048>;

// dst = Wᵀ·src through layer l, masked by the ReLU of that layer's input activation.
fn dense_t(l: u32, row: u32, src: ptr<function, array<f32, MAXD>>, dst: ptr<function, array<f32, MAXD>>, lid: u32) {
    let d = layer_dims(l);
    for (var i = 0u; i < d.x; i++) {
        (*dst)[i] = 0.0;
    }
    for (var i0 = 0u; i0 < d.x; i0 += TILE_IN) {
        for (var o0 = 0u; o0 < d.y; o0 += TILE_OUT) {
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
            for (var i = 0u; i < ni; i++) {
                var s = 0.0;
                for (var o = 0u; o < no; o++) {
                    s += tile[o * TILE_IN + i] * (*src)[o0 + o];
                }
                (*dst)[i0 + i] += s;
            }
        }
    }
    let at = row + act_offset(l);
    for (var i = 0u; i < d.x; i++) {
        if acts[at + i] <= 0.0 {
            (*dst)[i] = 0.0;
        }
    }
}

fn keep(row: u32, at: u32, len: u32, v: ptr<function, array<f32, MAXD>>) {
    for (var j = 0u; j < len; j++) {
        deltas[row + at + j] = (*v)[j];
    }
}

@compute @workgroup_size(64)
fn backward(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let n = linear_id(wg, nwg, lid, 64u);
    let live = n < step.n;
    let g = min(n, step.n - 1u);
    let arow = g * ACT_STRIDE;
    let hat = arow + act_offset(4u);
    let c = gates[2u * g];
    let q = vec4<f32>(quats[4u * g], quats[4u * g + 1u], quats[4u * g + 2u], quats[4u * g + 3u]);
    let norm = length(q);
    let unit = q / norm;

    var vh: array<f32, MAXD>;
    var tmp: array<f32, MAXD>;
    for (var j = 0u; j < HEADS; j++) {
        vh[j] = 0.0;
    }
    var v_gate = 0.0;
    var v_mean = vec3<f32>(0.0);
    var v_ls = vec3<f32>(0.0);
    var v_unit = vec4<f32>(0.0);
    for (var m = 0u; m <= M; m++) {
        let o = m * step.n + g;
        let gm = vec3<f32>(v_set_means[3u * o], v_set_means[3u * o + 1u], v_set_means[3u * o + 2u]);
        v_mean += gm;
        for (var k = 0u; k < 3u; k++) {
            let gl = v_set_log_scales[3u * o + k];
            v_ls[k] += gl;
            let h = acts[hat + H_SCALE + 3u * m + k];
            let d = multiplier(c, h);
            vh[H_SCALE + 3u * m + k] += gl * c * d.y / d.x;
            v_gate += gl * h * d.y / d.x;
        }
        for (var k = 0u; k < 4u; k++) {
            let gq = v_set_quats[4u * o + k];
            let h = acts[hat + H_ROT + 4u * m + k];
            let d = multiplier(c, h);
            v_unit[k] += gq * d.x;
            vh[H_ROT + 4u * m + k] += gq * unit[k] * c * d.y;
            v_gate += gq * unit[k] * h * d.y;
        }
        if m == M {
            continue;
        }
        let raw = vec3<f32>(acts[hat + H_POS + 3u * m], acts[hat + H_POS + 3u * m + 1u], acts[hat + H_POS + 3u * m + 2u]);
        if PAPER {
            let ha = acts[hat + H_APERTURE];
            let hb = acts[hat + H_BETA + m];
            let aperture = softplus(ha);
            let beta = sigmoid(hb);
            let len = max(length(raw), 1e-12);
            let dir = raw / len;
            let dot_g = dot(dir, gm);
            vh[H_APERTURE] += 0.5 * c * beta * dot_g * sigmoid(ha);
            vh[H_BETA + m] += 0.5 * aperture * c * dot_g * beta * (1.0 - beta);
            v_gate += 0.5 * aperture * beta * dot_g;
            let v_raw = 0.5 * aperture * c * beta * (gm - dir * dot_g) / len;
            vh[H_POS + 3u * m] += v_raw.x;
            vh[H_POS + 3u * m + 1u] += v_raw.y;
            vh[H_POS + 3u * m + 2u] += v_raw.z;
        } else {
            vh[H_POS + 3u * m] += c * gm.x;
            vh[H_POS + 3u * m + 1u] += c * gm.y;
            vh[H_POS + 3u * m + 2u] += c * gm.z;
            v_gate += dot(raw, gm);
        }
    }
    let drow = g * DELTA_STRIDE;
    if live {
        let vq = (v_unit - unit * dot(unit, v_unit)) / norm;
        for (var k = 0u; k < 3u; k++) {
            v_means[3u * g + k] = v_mean[k];
            v_log_scales[3u * g + k] = v_ls[k];
        }
        for (var k = 0u; k < 4u; k++) {
            v_quats[4u * g + k] = vq[k];
        }
        focus_terms[g] = v_gate * gates[2u * g + 1u];
        keep(drow, 3u * WIDTH, HEADS, &vh);
    }
    dense_t(3u, arow, &vh, &tmp, lid);
    if live { keep(drow, 2u * WIDTH, WIDTH, &tmp); }
    dense_t(2u, arow, &tmp, &vh, lid);
    if live { keep(drow, WIDTH, WIDTH, &vh); }
    dense_t(1u, arow, &vh, &tmp, lid);
    if live { keep(drow, 0u, WIDTH, &tmp); }
}
