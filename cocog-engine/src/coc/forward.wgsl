// The ends of h_θ's forward: `fold_camera` takes the step's camera into the first layer's
// bias; per base Gaussian, `embed` writes the input rows the trunk's matrix products read and
// `expand` turns the heads into the M + 1 sets. The trunk runs as tiled matrix products
// (mlp.rs).

@group(0) @binding(0) var<uniform> step: Step;
@group(0) @binding(1) var<storage, read> means: array<f32>;
@group(0) @binding(2) var<storage, read> log_scales: array<f32>;
@group(0) @binding(3) var<storage, read> quats: array<f32>;
@group(0) @binding(4) var<storage, read> focus: array<f32>;
// [Gaussian][ROW_DIM]: γ(μ) | exp(log-scale) | q/|q| (γ(camera centre) is in `camera`).
@group(0) @binding(5) var<storage, read_write> inputs: array<f32>;
// [Gaussian][HEADS], the last layer's outputs.
@group(0) @binding(6) var<storage, read> heads: array<f32>;
// The M + 1 sets, [set][base].
@group(0) @binding(7) var<storage, read_write> set_means: array<f32>;
@group(0) @binding(8) var<storage, read_write> set_log_scales: array<f32>;
@group(0) @binding(9) var<storage, read_write> set_quats: array<f32>;
// Per Gaussian: the gate c, ∂c/∂focus[view], the normalised depth d and the aperture K.
@group(0) @binding(10) var<storage, read_write> gates: array<vec4<f32>>;
// Per training view, the lens variant's aperture a (K = a·d).
@group(0) @binding(11) var<storage, read> apertures: array<f32>;
// h_θ's flat parameters, and the step's camera terms: [WIDTH] the first layer's bias plus its
// camera columns times γ(camera centre), then [CAMERA_DIM] γ(camera centre) itself, which
// the weight gradient of those columns multiplies.
@group(0) @binding(12) var<storage, read> weights: array<f32>;
@group(0) @binding(13) var<storage, read_write> camera: array<f32>;

fn put_embedding(x: vec3<f32>, freqs: u32, at: u32) -> u32 {
    var k = at;
    inputs[k] = x.x; inputs[k + 1u] = x.y; inputs[k + 2u] = x.z;
    k += 3u;
    for (var f = 0u; f < freqs; f++) {
        let s = x * f32(1u << f);
        let sn = sin(s);
        let cs = cos(s);
        inputs[k] = sn.x; inputs[k + 1u] = sn.y; inputs[k + 2u] = sn.z;
        inputs[k + 3u] = cs.x; inputs[k + 4u] = cs.y; inputs[k + 5u] = cs.z;
        k += 6u;
    }
    return k;
}

// Component j of NeRF's embedding of x (without π) at `freqs` frequencies: x, then sin and
// cos of 2^f·x per frequency f, as put_embedding lays them out.
fn embedding(x: vec3<f32>, j: u32) -> f32 {
    if j < 3u {
        return x[j];
    }
    let f = (j - 3u) / 6u;
    let r = (j - 3u) % 6u;
    let s = x * f32(1u << f);
    if r < 3u {
        return sin(s)[r];
    }
    return cos(s)[r - 3u];
}

fn base_mean(g: u32) -> vec3<f32> {
    return vec3<f32>(means[3u * g], means[3u * g + 1u], means[3u * g + 2u]);
}

fn base_unit_quat(g: u32) -> vec4<f32> {
    let q = vec4<f32>(quats[4u * g], quats[4u * g + 1u], quats[4u * g + 2u], quats[4u * g + 3u]);
    return q / length(q);
}

@compute @workgroup_size(64)
fn embed(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let g = linear_id(wg, nwg, lid, 64u);
    if g >= step.n {
        return;
    }
    let k = put_embedding((base_mean(g) - step.origin) / step.scale, MEAN_FREQS, g * ROW_DIM);
    for (var j = 0u; j < 3u; j++) {
        inputs[k + j] = exp(log_scales[3u * g + j]) / step.scale;
    }
    let unit = base_unit_quat(g);
    for (var j = 0u; j < 4u; j++) {
        inputs[k + 3u + j] = unit[j];
    }
}

// γ(camera centre), computed once for fold_camera's 64 invocations.
var<workgroup> camera_embedding: array<f32, CAMERA_DIM>;

// One workgroup; every Gaussian's first-layer sum then starts from camera[o].
@compute @workgroup_size(64)
fn fold_camera(@builtin(local_invocation_index) lid: u32) {
    let x = (step.centre - step.origin) / step.scale;
    for (var j = lid; j < CAMERA_DIM; j += 64u) {
        let e = embedding(x, j);
        camera_embedding[j] = e;
        camera[WIDTH + j] = e;
    }
    workgroupBarrier();
    for (var o = lid; o < WIDTH; o += 64u) {
        let row = W0 + o * IN_DIM + MEAN_DIM;
        var s = weights[W0_BIAS + o];
        for (var j = 0u; j < CAMERA_DIM; j++) {
            s += weights[row + j] * camera_embedding[j];
        }
        camera[o] = s;
    }
}

@compute @workgroup_size(64)
fn expand(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let g = linear_id(wg, nwg, lid, 64u);
    if g >= step.n {
        return;
    }
    let mean = base_mean(g);
    let unit = base_unit_quat(g);
    let h = g * HEADS;
    let dist = length(mean - step.centre) / step.scale;
    let focus_distance = focus[step.view];
    let diff = 1.0 / dist - 1.0 / focus_distance;
    // The code variant takes the released code's |1/d − 1/d_F| in the scene's own units (the
    // frame's ÷ D), and its offsets c·raw in them too. Taken in the frame, as the other
    // variants' are, its spread was D² times the released code's.
    let gate_unit = select(step.scale, 1.0, PAPER || LENS);
    let c = step.aperture * abs(diff) / gate_unit;
    var aperture_k = 0.0;
    if LENS {
        aperture_k = apertures[step.view] * dist;
    } else if PAPER {
        aperture_k = softplus(heads[h + H_APERTURE]);
    }
    gates[g] = vec4<f32>(c, step.aperture * sign(diff) / (focus_distance * focus_distance * gate_unit), dist, aperture_k);

    // The copies' offsets (normalised), then (CENTRED) less their mean.
    var shifts: array<vec3<f32>, M>;
    var mean_shift = vec3<f32>(0.0);
    for (var m = 0u; m < M; m++) {
        let raw = vec3<f32>(heads[h + H_POS + 3u * m], heads[h + H_POS + 3u * m + 1u], heads[h + H_POS + 3u * m + 2u]);
        if PAPER || LENS {
            let beta = sigmoid(heads[h + H_BETA + m]);
            shifts[m] = 0.5 * aperture_k * c * beta * raw / max(length(raw), 1e-12);
        } else {
            shifts[m] = c * raw / step.scale;
        }
        mean_shift += shifts[m] / f32(M);
    }
    for (var m = 0u; m <= M; m++) {
        var shift = vec3<f32>(0.0);
        if m < M {
            shift = shifts[m];
            if CENTRED {
                shift -= mean_shift;
            }
        }
        let o = m * step.n + g;
        let p = mean + step.scale * shift;
        // The base set's multipliers stay 1 unless it is modulated.
        var cm = c;
        if m == M && !MODULATE_BASE {
            cm = 0.0;
        }
        set_means[3u * o] = p.x; set_means[3u * o + 1u] = p.y; set_means[3u * o + 2u] = p.z;
        for (var j = 0u; j < 3u; j++) {
            set_log_scales[3u * o + j] = log_scales[3u * g + j] + log(multiplier(cm, heads[h + H_SCALE + 3u * m + j]).x);
        }
        for (var j = 0u; j < 4u; j++) {
            set_quats[4u * o + j] = unit[j] * multiplier(cm, heads[h + H_ROT + 4u * m + j]).x;
        }
    }
}
