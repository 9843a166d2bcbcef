// The per-Gaussian start of the adjoint, one thread per base Gaussian: sums the M + 1 sets'
// gradients into the base and turns them into the gradient of h_θ's heads (what the trunk's
// transposed matrix products take back, mlp.rs) and this Gaussian's share of the focus
// distance's gradient. h_θ's input is detached: nothing flows into the base through it.

@group(0) @binding(0) var<uniform> step: Step;
@group(0) @binding(1) var<storage, read> quats: array<f32>;
// [Gaussian][HEADS], the forward's heads.
@group(0) @binding(2) var<storage, read> heads: array<f32>;
// Per Gaussian: c, ∂c/∂focus[view], the normalised depth d, the aperture K.
@group(0) @binding(3) var<storage, read> gates: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read> v_set_means: array<f32>;
@group(0) @binding(5) var<storage, read> v_set_log_scales: array<f32>;
@group(0) @binding(6) var<storage, read> v_set_quats: array<f32>;
@group(0) @binding(7) var<storage, read_write> v_means: array<f32>;
@group(0) @binding(8) var<storage, read_write> v_log_scales: array<f32>;
@group(0) @binding(9) var<storage, read_write> v_quats: array<f32>;
// [Gaussian][HEADS]: ∂loss/∂heads.
@group(0) @binding(10) var<storage, read_write> d_heads: array<f32>;
// Per Gaussian, its shares of ∂loss/∂focus[view] and (lens variant) ∂loss/∂aperture[view].
@group(0) @binding(11) var<storage, read_write> focus_terms: array<vec2<f32>>;

@compute @workgroup_size(64)
fn backward(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let g = linear_id(wg, nwg, lid, 64u);
    if g >= step.n {
        return;
    }
    let hh = g * HEADS;
    let dh = g * HEADS;
    let gate = gates[g];
    let c = gate.x;
    let aperture_k = gate.w;
    var v_k = 0.0;
    let q = vec4<f32>(quats[4u * g], quats[4u * g + 1u], quats[4u * g + 2u], quats[4u * g + 3u]);
    let norm = length(q);
    let unit = q / norm;

    // Each head's gradient below is written once (every index is a different head, and each
    // variant writes all of its own), so d_heads needs no zeroing and no read-back.
    // Offsets are D × normalised ones, whose gradient is D × the world one; centring
    // subtracts the copies' mean offset, so each offset's gradient loses their mean.
    var g_mean = vec3<f32>(0.0);
    if CENTRED {
        for (var m = 0u; m < M; m++) {
            let o = m * step.n + g;
            g_mean += vec3<f32>(v_set_means[3u * o], v_set_means[3u * o + 1u], v_set_means[3u * o + 2u]) / f32(M);
        }
    }
    var v_gate = 0.0;
    var v_mean = vec3<f32>(0.0);
    var v_ls = vec3<f32>(0.0);
    var v_unit = vec4<f32>(0.0);
    for (var m = 0u; m <= M; m++) {
        let o = m * step.n + g;
        var cm = c;
        if m == M && !MODULATE_BASE {
            cm = 0.0;
        }
        let gm = vec3<f32>(v_set_means[3u * o], v_set_means[3u * o + 1u], v_set_means[3u * o + 2u]);
        v_mean += gm;
        for (var k = 0u; k < 3u; k++) {
            let gl = v_set_log_scales[3u * o + k];
            v_ls[k] += gl;
            let h = heads[hh + H_SCALE + 3u * m + k];
            let d = multiplier(cm, h);
            d_heads[dh + H_SCALE + 3u * m + k] = gl * cm * d.y / d.x;
            v_gate += gl * h * d.y / d.x;
        }
        for (var k = 0u; k < 4u; k++) {
            let gq = v_set_quats[4u * o + k];
            let h = heads[hh + H_ROT + 4u * m + k];
            let d = multiplier(cm, h);
            v_unit[k] += gq * d.x;
            d_heads[dh + H_ROT + 4u * m + k] = gq * unit[k] * cm * d.y;
            v_gate += gq * unit[k] * h * d.y;
        }
        if m == M {
            continue;
        }
        let raw = vec3<f32>(heads[hh + H_POS + 3u * m], heads[hh + H_POS + 3u * m + 1u], heads[hh + H_POS + 3u * m + 2u]);
        let g_off = step.scale * (gm - g_mean);
        if PAPER || LENS {
            let hb = heads[hh + H_BETA + m];
            let beta = sigmoid(hb);
            let len = max(length(raw), 1e-12);
            let dir = raw / len;
            let dot_g = dot(dir, g_off);
            v_k += 0.5 * c * beta * dot_g;
            d_heads[dh + H_BETA + m] = 0.5 * aperture_k * c * dot_g * beta * (1.0 - beta);
            v_gate += 0.5 * aperture_k * beta * dot_g;
            let v_raw = 0.5 * aperture_k * c * beta * (g_off - dir * dot_g) / len;
            d_heads[dh + H_POS + 3u * m] = v_raw.x;
            d_heads[dh + H_POS + 3u * m + 1u] = v_raw.y;
            d_heads[dh + H_POS + 3u * m + 2u] = v_raw.z;
        } else {
            // The offset is c·raw in world units (forward.wgsl).
            let g_world = gm - g_mean;
            d_heads[dh + H_POS + 3u * m] = c * g_world.x;
            d_heads[dh + H_POS + 3u * m + 1u] = c * g_world.y;
            d_heads[dh + H_POS + 3u * m + 2u] = c * g_world.z;
            v_gate += dot(raw, g_world);
        }
    }
    let vq = (v_unit - unit * dot(unit, v_unit)) / norm;
    for (var k = 0u; k < 3u; k++) {
        v_means[3u * g + k] = v_mean[k];
        v_log_scales[3u * g + k] = v_ls[k];
    }
    for (var k = 0u; k < 4u; k++) {
        v_quats[4u * g + k] = vq[k];
    }
    if PAPER {
        d_heads[dh + H_APERTURE] = v_k * sigmoid(heads[hh + H_APERTURE]);
    }
    // The lens variant's K = a·d; the others have no per-photo aperture.
    var v_a = 0.0;
    if LENS {
        v_a = v_k * gate.z;
    }
    focus_terms[g] = vec2<f32>(v_gate * gate.y, v_a);
}
