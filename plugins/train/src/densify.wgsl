// INRIA densify_and_prune on the GPU, the same rule as densify.rs's `plan_densify` (its test
// oracle). Four passes, with exclusive prefix sums between them:
//   classify   per Gaussian: keep (not split), clone, split flags, each scanned into slots;
//   candidates the densified set before pruning, in INRIA order: kept originals, clones, first
//              split children, second split children; split children get their sampled mean
//              and shrunk scale, and every candidate's depth widens the [min, max] range;
//   survive    per candidate: the (depth-weighted) opacity and large-scale prune;
// gather_rows.wgsl then moves each surviving candidate's rows to its scanned slot.
// Each scan holds one slot more than its input, so that slot ends up as the total.

struct Params {
    n: u32,
    // Candidate slots: 2n, the most the densified set can hold before pruning.
    bound: u32,
    seed_lo: u32,
    seed_hi: u32,
    iteration: u32,
    // 0: one opacity threshold; 1: depth along `forward` from `origin`; 2: distance from it.
    depth_mode: u32,
    pad0: u32,
    pad1: u32,
    grad_threshold: f32,
    // Largest scale up to which a hot Gaussian is cloned rather than split.
    dense: f32,
    min_opacity: f32,
    // Gaussians whose largest scale exceeds this are pruned (infinite when the rule is off).
    large: f32,
    depth_range: f32,
    pad2: f32,
    pad3: f32,
    pad4: f32,
    origin: vec4<f32>,
    forward: vec4<f32>,
}

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> accum: array<f32>;
@group(0) @binding(2) var<storage, read> denom: array<f32>;
@group(0) @binding(3) var<storage, read> means: array<f32>;
@group(0) @binding(4) var<storage, read> log_scales: array<f32>;
@group(0) @binding(5) var<storage, read> quats: array<f32>;
@group(0) @binding(6) var<storage, read> opacity_logits: array<f32>;
@group(0) @binding(7) var<storage, read_write> keep_slots: array<u32>;
@group(0) @binding(8) var<storage, read_write> clone_slots: array<u32>;
@group(0) @binding(9) var<storage, read_write> split_slots: array<u32>;
// Per candidate: its source Gaussian in bits 0..29, its kind (0 keep, 1 clone, 2 split) above.
@group(0) @binding(10) var<storage, read_write> candidates: array<u32>;
// Per candidate: a split child's mean and log-scales (unused for the others).
@group(0) @binding(11) var<storage, read_write> child_shapes: array<f32>;
// Order-preserving u32 codes of the lowest and highest candidate depth.
@group(0) @binding(12) var<storage, read_write> depth_range: array<atomic<u32>, 2>;
@group(0) @binding(13) var<storage, read_write> survive_slots: array<u32>;

const KIND_KEEP: u32 = 0u;
const KIND_CLONE: u32 = 1u;
const KIND_SPLIT: u32 = 2u;
const SPLIT_CHILDREN: u32 = 2u;
// INRIA divides a split child's scale by 0.8 · N.
const SPLIT_SCALE_DIV: f32 = 1.6;
const TAU: f32 = 6.283185307179586;

fn linear(gid: vec3<u32>, nwg: vec3<u32>) -> u32 {
    return gid.x + gid.y * nwg.x * 256u;
}

fn max_scale(ls: vec3<f32>) -> f32 {
    return max(exp(ls.x), max(exp(ls.y), exp(ls.z)));
}

fn log_scale_of(i: u32) -> vec3<f32> {
    return vec3<f32>(log_scales[3u * i], log_scales[3u * i + 1u], log_scales[3u * i + 2u]);
}

fn mean_of(i: u32) -> vec3<f32> {
    return vec3<f32>(means[3u * i], means[3u * i + 1u], means[3u * i + 2u]);
}

fn is_hot(i: u32) -> bool {
    let d = denom[i];
    let g = select(0.0, accum[i] / d, d > 0.0);
    return g >= params.grad_threshold;
}

// PCG hash (Jarzynski & Olano 2020); densify.rs's `split_noise` computes the same words.
fn pcg(v: u32) -> u32 {
    let state = v * 747796405u + 2891336453u;
    let word = ((state >> ((state >> 28u) + 4u)) ^ state) * 277803737u;
    return (word >> 22u) ^ word;
}

// A standard normal (Box–Muller) for axis `axis` of child `child` of Gaussian `i`, drawn from
// the seed and the iteration alone, so a resumed run draws the same children.
fn split_normal(i: u32, child: u32, axis: u32) -> f32 {
    let key = pcg(params.seed_lo ^ pcg(params.seed_hi ^ pcg(params.iteration ^ pcg(i ^ pcg(child * 3u + axis)))));
    let u1 = f32((pcg(key ^ 1u) >> 8u) + 1u) * 5.9604645e-8;
    let u2 = f32(pcg(key ^ 2u) >> 8u) * 5.9604645e-8;
    return sqrt(-2.0 * log(u1)) * cos(TAU * u2);
}

// quat_to_rot comes from the engine (cocog_engine::splat::QUAT_TO_ROT_WGSL), prepended.
fn rotation(i: u32) -> mat3x3<f32> {
    let q = vec4<f32>(quats[4u * i], quats[4u * i + 1u], quats[4u * i + 2u], quats[4u * i + 3u]);
    return quat_to_rot(q / max(length(q), 1e-12));
}

fn depth(p: vec3<f32>) -> f32 {
    let d = p - params.origin.xyz;
    if (params.depth_mode == 1u) {
        return dot(d, params.forward.xyz);
    }
    return length(d);
}

// Monotone map of f32 onto u32, so atomicMin/Max order depths.
fn order_code(f: f32) -> u32 {
    let b = bitcast<u32>(f);
    return select(b | 0x80000000u, ~b, (b & 0x80000000u) != 0u);
}

fn from_order_code(c: u32) -> f32 {
    return bitcast<f32>(select(~c, c & 0x7fffffffu, (c & 0x80000000u) != 0u));
}

fn widen_depth_range(p: vec3<f32>) {
    if (params.depth_mode != 0u) {
        let c = order_code(depth(p));
        atomicMin(&depth_range[0], c);
        atomicMax(&depth_range[1], c);
    }
}

@compute @workgroup_size(256)
fn classify(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = linear(gid, nwg);
    if (i == 0u) {
        atomicStore(&depth_range[0], 0xffffffffu);
        atomicStore(&depth_range[1], 0u);
    }
    if (i > params.n) {
        return;
    }
    var keep = 0u;
    var clone = 0u;
    var split = 0u;
    if (i < params.n) {
        let hot = is_hot(i);
        let small = max_scale(log_scale_of(i)) <= params.dense;
        split = select(0u, 1u, hot && !small);
        clone = select(0u, 1u, hot && small);
        keep = 1u - split;
    }
    keep_slots[i] = keep;
    clone_slots[i] = clone;
    split_slots[i] = split;
}

@compute @workgroup_size(256)
fn place_candidates(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = linear(gid, nwg);
    if (i >= params.n) {
        return;
    }
    let kept = keep_slots[params.n];
    let cloned = clone_slots[params.n];
    let split = split_slots[params.n];
    let mean = mean_of(i);
    if (keep_slots[i + 1u] != keep_slots[i]) {
        candidates[keep_slots[i]] = i | (KIND_KEEP << 30u);
        widen_depth_range(mean);
    }
    if (clone_slots[i + 1u] != clone_slots[i]) {
        candidates[kept + clone_slots[i]] = i | (KIND_CLONE << 30u);
        widen_depth_range(mean);
    }
    if (split_slots[i + 1u] != split_slots[i]) {
        let ls = log_scale_of(i);
        let scale = exp(ls);
        let r = rotation(i);
        let child_ls = log(scale / SPLIT_SCALE_DIV);
        for (var c = 0u; c < SPLIT_CHILDREN; c++) {
            let z = vec3<f32>(split_normal(i, c, 0u), split_normal(i, c, 1u), split_normal(i, c, 2u));
            let p = mean + r * (scale * z);
            let slot = kept + cloned + c * split + split_slots[i];
            candidates[slot] = i | (KIND_SPLIT << 30u);
            child_shapes[6u * slot] = p.x;
            child_shapes[6u * slot + 1u] = p.y;
            child_shapes[6u * slot + 2u] = p.z;
            child_shapes[6u * slot + 3u] = child_ls.x;
            child_shapes[6u * slot + 4u] = child_ls.y;
            child_shapes[6u * slot + 5u] = child_ls.z;
            widen_depth_range(p);
        }
    }
}

@compute @workgroup_size(256)
fn mark_survivors(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let slot = linear(gid, nwg);
    if (slot > params.bound) {
        return;
    }
    let total = keep_slots[params.n] + clone_slots[params.n] + SPLIT_CHILDREN * split_slots[params.n];
    if (slot >= total) {
        survive_slots[slot] = 0u;
        return;
    }
    let word = candidates[slot];
    let src = word & 0x3fffffffu;
    var mean = mean_of(src);
    var ls = log_scale_of(src);
    if ((word >> 30u) == KIND_SPLIT) {
        mean = vec3<f32>(child_shapes[6u * slot], child_shapes[6u * slot + 1u], child_shapes[6u * slot + 2u]);
        ls = vec3<f32>(child_shapes[6u * slot + 3u], child_shapes[6u * slot + 4u], child_shapes[6u * slot + 5u]);
    }
    var threshold = params.min_opacity;
    if (params.depth_mode != 0u) {
        let lo = from_order_code(atomicLoad(&depth_range[0]));
        let hi = from_order_code(atomicLoad(&depth_range[1]));
        let span = max(hi - lo, 1.17549435e-38);
        threshold = params.min_opacity / (1.0 + (params.depth_range - 1.0) * (depth(mean) - lo) / span);
    }
    let opacity = 1.0 / (1.0 + exp(-opacity_logits[src]));
    let pruned = opacity < threshold || max_scale(ls) > params.large;
    survive_slots[slot] = select(1u, 0u, pruned);
}
