// Compositing backward: one 16×16 workgroup per (tile, image) replays the tile's list back
// to front from the last Gaussian any of its pixels used, recovering each transmittance by
// division, and accumulates per-Gaussian screen-space gradients with atomics.
// v_proj layout per Gaussian: mean2d (2), conic (3), colour (3), opacity, depth.
// `add_grad` and the `v_proj` binding (slot 9) are prepended by the host: native float
// atomics where the adapter has them, a compare-exchange loop otherwise.

struct Params {
    width: u32,
    height: u32,
    tiles_x: u32,
    tiles_y: u32,
}

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> backgrounds: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> ranges: array<vec2<u32>>;
@group(0) @binding(3) var<storage, read> tile_values: array<u32>;
@group(0) @binding(4) var<storage, read> projected: array<vec4<f32>>;
@group(0) @binding(5) var<storage, read> out_t: array<f32>;
@group(0) @binding(6) var<storage, read> out_last: array<u32>;
@group(0) @binding(7) var<storage, read> v_rgba: array<vec4<f32>>;
@group(0) @binding(8) var<storage, read> v_depth: array<f32>;

const BATCH: u32 = 256u;
const ALPHA_MAX: f32 = 0.99;
const ALPHA_MIN: f32 = 1.0 / 255.0;
const V_STRIDE: u32 = 10u;

var<workgroup> batch_a: array<vec4<f32>, 256>;
var<workgroup> batch_b: array<vec4<f32>, 256>;
var<workgroup> batch_c: array<vec4<f32>, 256>;
var<workgroup> batch_id: array<u32, 256>;
var<workgroup> tile_end: atomic<u32>;
var<workgroup> tile_end_snapshot: u32;

@compute @workgroup_size(16, 16, 1)
fn rasterize_backward(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(local_invocation_id) lid: vec3<u32>,
    @builtin(local_invocation_index) tid: u32,
) {
    let image = wid.z;
    let tile = (image * params.tiles_y + wid.y) * params.tiles_x + wid.x;
    let px = wid.x * 16u + lid.x;
    let py = wid.y * 16u + lid.y;
    let inside = px < params.width && py < params.height;
    let centre = vec2<f32>(f32(px) + 0.5, f32(py) + 0.5);
    let range = ranges[tile];
    let pix = (image * params.height + py) * params.width + px;

    var t_final = 1.0;
    var last = range.x;
    var v_out = vec4<f32>(0.0);
    var v_d = 0.0;
    if (inside) {
        t_final = out_t[pix];
        last = out_last[pix];
        v_out = v_rgba[pix];
        v_d = v_depth[pix];
    }
    if (tid == 0u) {
        atomicStore(&tile_end, range.x);
    }
    workgroupBarrier();
    atomicMax(&tile_end, last);
    workgroupBarrier();
    if (tid == 0u) {
        tile_end_snapshot = atomicLoad(&tile_end);
    }
    let end = workgroupUniformLoad(&tile_end_snapshot);

    var t = t_final;
    var behind = t_final * backgrounds[image].xyz;
    var behind_depth = 0.0;
    let num_batches = (end - range.x + BATCH - 1u) / BATCH;
    for (var b = 0u; b < num_batches; b++) {
        workgroupBarrier();
        let batch_end = end - b * BATCH;
        let batch_start = max(range.x, batch_end - min(batch_end, BATCH));
        if (batch_start + tid < batch_end) {
            let g = tile_values[batch_start + tid];
            batch_id[tid] = g;
            batch_a[tid] = projected[3u * g];
            batch_b[tid] = projected[3u * g + 1u];
            batch_c[tid] = projected[3u * g + 2u];
        }
        workgroupBarrier();
        for (var j = batch_end - batch_start; j > 0u; j--) {
            let k = j - 1u;
            if (batch_start + k >= last) {
                continue;
            }
            let a = batch_a[k];
            let conic = batch_b[k].xyz;
            let d = a.xy - centre;
            let power = -0.5 * (conic.x * d.x * d.x + conic.z * d.y * d.y) - conic.y * d.x * d.y;
            if (power > 0.0) {
                continue;
            }
            let gauss = exp(power);
            let raw = a.w * gauss;
            let alpha = min(ALPHA_MAX, raw);
            if (alpha < ALPHA_MIN) {
                continue;
            }
            let one_minus = 1.0 - alpha;
            t = t / one_minus;
            let w = alpha * t;
            let c = batch_c[k].xyz;
            var v_alpha = v_out.w * t_final / one_minus;
            v_alpha += dot(v_out.xyz, t * c - behind / one_minus);
            v_alpha += v_d * (t * a.z - behind_depth / one_minus);
            behind += c * w;
            behind_depth += a.z * w;

            let base = batch_id[k] * V_STRIDE;
            add_grad(base + 5u, w * v_out.x);
            add_grad(base + 6u, w * v_out.y);
            add_grad(base + 7u, w * v_out.z);
            add_grad(base + 9u, w * v_d);
            if (raw <= ALPHA_MAX) {
                let v_power = v_alpha * alpha;
                add_grad(base + 0u, -v_power * (conic.x * d.x + conic.y * d.y));
                add_grad(base + 1u, -v_power * (conic.z * d.y + conic.y * d.x));
                add_grad(base + 2u, -v_power * 0.5 * d.x * d.x);
                add_grad(base + 3u, -v_power * d.x * d.y);
                add_grad(base + 4u, -v_power * 0.5 * d.y * d.y);
                add_grad(base + 8u, v_alpha * gauss);
            }
        }
    }
}
