// Compositing backward: one workgroup per SUB×SUB block of a 16×16 tile (SUB, 16 or 8, from the
// host) and image replays the tile's list back to front, each subgroup (or pixel) from the last
// Gaussian it used, recovering each transmittance by division, and accumulates per-Gaussian
// screen-space gradients with atomics. Blocks of 8×8 walk each list four times over, but give a
// small frame (a 100×75 photo has 35 tiles) four times the workgroups to spread over a GPU.
// v_proj layout per Gaussian: mean2d (2), conic (3), colour (3), opacity, depth.
// The host appends `add_grad` and the `v_proj` binding (slot 9) — native float atomics where
// the adapter has them, a compare-exchange loop otherwise — and `flush`, which either adds
// each pixel's gradient directly or first sums it over the subgroup (one atomic per
// subgroup instead of one per pixel), and `walk_end`, where each invocation's walk starts: its
// own last Gaussian, or its subgroup's (so the subgroup stays in step for the sums). The host also prepends `DEPTH_GRAD` and `depth_grad`:
// the binding of `v_depth` (slot 8) where a loss needs depth, or a constant 0 that compiles the
// depth channel out (no read, no compositing of depth, one atomic fewer per Gaussian).
// With `splits` S > 1, workgroup x = block × S + c walks only chunk c of its tile's list (the
// forward's split, rasterize.wgsl): a pixel that composited past the chunk starts from the
// transmittance the forward recorded at the chunk's end, and from what lies behind it, its
// final colour and depth less those in front of that boundary.

struct Params {
    width: u32,
    height: u32,
    tiles_x: u32,
    tiles_y: u32,
    pixels: u32,
    splits: u32,
    // Shortest chunk: lists shorter than splits × min_chunk have fewer, the rest none.
    min_chunk: u32,
}

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> backgrounds: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> ranges: array<vec2<u32>>;
@group(0) @binding(3) var<storage, read> tile_values: array<u32>;
@group(0) @binding(4) var<storage, read> projected: array<vec4<f32>>;
@group(0) @binding(5) var<storage, read> out_t: array<f32>;
@group(0) @binding(6) var<storage, read> out_last: array<u32>;
@group(0) @binding(7) var<storage, read> v_rgba: array<vec4<f32>>;
@group(0) @binding(10) var<storage, read> chunk_state: array<vec4<f32>>;
// Read only with the depth channel; bound either way (naga keeps a binding that only dead code
// reads in the layout).
@group(0) @binding(11) var<storage, read> chunk_depth: array<f32>;

const BATCH: u32 = SUB * SUB;
// Blocks per tile side.
const PER_TILE: u32 = 16u / SUB;
const ALPHA_MAX: f32 = 0.99;
const ALPHA_MIN: f32 = 1.0 / 255.0;
const V_STRIDE: u32 = 10u;

var<workgroup> batch_a: array<vec4<f32>, BATCH>;
var<workgroup> batch_b: array<vec4<f32>, BATCH>;
var<workgroup> batch_c: array<vec4<f32>, BATCH>;
var<workgroup> batch_id: array<u32, BATCH>;
var<workgroup> tile_end: atomic<u32>;
var<workgroup> tile_end_snapshot: u32;

// One-dimensional workgroup: subgroup builtins are only defined for those.
@compute @workgroup_size(BATCH)
fn rasterize_backward(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(local_invocation_index) tid: u32,
    // SUBGROUP_PARAM
) {
    let lid = vec2<u32>(tid % SUB, tid / SUB);
    // A block's chunks are neighbours in the grid, so however an adapter deals consecutive
    // workgroups out (lavapipe: ranges of them to each thread), a long list's first chunks do
    // not all land together.
    let image = wid.z;
    let part = wid.x % params.splits;
    let bx = wid.x / params.splits;
    let tile = (image * params.tiles_y + wid.y / PER_TILE) * params.tiles_x + bx / PER_TILE;
    let px = bx * SUB + lid.x;
    let py = wid.y * SUB + lid.y;
    let inside = px < params.width && py < params.height;
    let centre = vec2<f32>(f32(px) + 0.5, f32(py) + 0.5);
    let range = ranges[tile];
    let pix = (image * params.height + py) * params.width + px;
    let chunk = max(params.min_chunk, (range.y - range.x + params.splits - 1u) / params.splits);
    let chunk_begin = min(range.y, range.x + part * chunk);
    let chunk_end = min(range.y, chunk_begin + chunk);
    // A chunk past a short list: nothing to walk (range is the same for the whole workgroup).
    if (part > 0u && chunk_begin == range.y) {
        return;
    }

    var t_final = 1.0;
    var last = range.x;
    var v_out = vec4<f32>(0.0);
    var v_d = 0.0;
    if (inside) {
        t_final = out_t[pix];
        last = out_last[pix];
        v_out = v_rgba[pix];
        v_d = depth_grad(pix);
    }
    var t = t_final;
    var behind = t_final * backgrounds[image].xyz;
    var behind_depth = 0.0;
    if (inside && last > chunk_end) {
        // Only when split: unsplit, the one chunk ends with the list.
        let at = part * params.pixels + pix;
        let fin = (params.splits - 1u) * params.pixels + pix;
        let front = chunk_state[at];
        t = front.w;
        behind += chunk_state[fin].xyz - front.xyz;
        if (DEPTH_GRAD) {
            behind_depth = chunk_depth[fin] - chunk_depth[at];
        }
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
    // This chunk's part of the Gaussians some pixel of the block composited.
    let end = max(chunk_begin, min(chunk_end, workgroupUniformLoad(&tile_end_snapshot)));

    let my_end = walk_end(last);
    let num_batches = (end - chunk_begin + BATCH - 1u) / BATCH;
    for (var b = 0u; b < num_batches; b++) {
        workgroupBarrier();
        let batch_end = end - b * BATCH;
        let batch_start = max(chunk_begin, batch_end - min(batch_end, BATCH));
        if (batch_start + tid < batch_end) {
            let g = tile_values[batch_start + tid];
            batch_id[tid] = g;
            batch_a[tid] = projected[3u * g];
            batch_b[tid] = projected[3u * g + 1u];
            batch_c[tid] = projected[3u * g + 2u];
        }
        workgroupBarrier();
        // Gaussians at or past `my_end` are behind every pixel this invocation (or its
        // subgroup) composited: skip them.
        for (var j = clamp(my_end, batch_start, batch_end) - batch_start; j > 0u; j--) {
            let k = j - 1u;
            // A subgroup walks the same Gaussians in lockstep (the bounds are uniform in it),
            // so `flush` may reduce across it; non-contributing pixels add zeros.
            // v_proj slots 0-3, 4-7 and 8-9 (see the layout above).
            var g0 = vec4<f32>(0.0);
            var g1 = vec4<f32>(0.0);
            var g2 = vec2<f32>(0.0);
            var contributes = false;
            let a = batch_a[k];
            let conic = batch_b[k].xyz;
            let d = a.xy - centre;
            let power = -0.5 * (conic.x * d.x * d.x + conic.z * d.y * d.y) - conic.y * d.x * d.y;
            let gauss = exp(min(power, 0.0));
            let raw = a.w * gauss;
            let alpha = min(ALPHA_MAX, raw);
            if (batch_start + k < last && power <= 0.0 && alpha >= ALPHA_MIN) {
                contributes = true;
                let one_minus = 1.0 - alpha;
                t = t / one_minus;
                let w = alpha * t;
                let c = batch_c[k].xyz;
                var v_alpha = v_out.w * t_final / one_minus;
                v_alpha += dot(v_out.xyz, t * c - behind / one_minus);
                if (DEPTH_GRAD) {
                    v_alpha += v_d * (t * a.z - behind_depth / one_minus);
                    behind_depth += a.z * w;
                    g2.y = w * v_d;
                }
                behind += c * w;
                g1 = vec4<f32>(0.0, w * v_out.xyz);
                if (raw <= ALPHA_MAX) {
                    let v_power = v_alpha * alpha;
                    g0 = -v_power * vec4<f32>(
                        conic.x * d.x + conic.y * d.y,
                        conic.z * d.y + conic.y * d.x,
                        0.5 * d.x * d.x,
                        d.x * d.y,
                    );
                    g1.x = -v_power * 0.5 * d.y * d.y;
                    g2.x = v_alpha * gauss;
                }
            }
            flush(batch_id[k] * V_STRIDE, contributes, g0, g1, g2, sg_lane);
        }
    }
}
