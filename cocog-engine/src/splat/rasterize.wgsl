// Front-to-back compositing: one workgroup per SUB×SUB block of a 16×16 tile (SUB, 16 or 8,
// from the host) and image, one thread per pixel. Each batch of up to SUB² projected Gaussians
// of the tile's list is staged in shared memory by all threads; the workgroup stops once every
// pixel's transmittance has run out. A pixel's result does not depend on SUB.
// With `splits` S > 1 (the host then compiles SPLIT in) the backward walks each tile's list in S chunks, each its own workgroup:
// one long list would otherwise be one workgroup's serial walk while the GPU idles. So each
// pixel records what the backward of a chunk starts from: at every chunk boundary it reached
// still compositing, the transmittance and the colour and depth in front (slot k − 1 for
// boundary k), and at the end its final ones (slot S − 1).

struct Params {
    width: u32,
    height: u32,
    tiles_x: u32,
    tiles_y: u32,
    // Pixels of every image: the stride of a chunk slot.
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
@group(0) @binding(5) var<storage, read_write> out_rgba: array<vec4<f32>>;
@group(0) @binding(6) var<storage, read_write> out_depth: array<f32>;
@group(0) @binding(7) var<storage, read_write> out_t: array<f32>;
@group(0) @binding(8) var<storage, read_write> out_last: array<u32>;
// [slot][pixel]: (colour in front, transmittance), and depth in front.
@group(0) @binding(9) var<storage, read_write> chunk_state: array<vec4<f32>>;
@group(0) @binding(10) var<storage, read_write> chunk_depth: array<f32>;

const BATCH: u32 = SUB * SUB;
// Blocks per tile side.
const PER_TILE: u32 = 16u / SUB;
const ALPHA_MAX: f32 = 0.99;
const ALPHA_MIN: f32 = 1.0 / 255.0;
const T_MIN: f32 = 1e-4;

var<workgroup> batch_a: array<vec4<f32>, BATCH>;
var<workgroup> batch_b: array<vec4<f32>, BATCH>;
var<workgroup> batch_c: array<vec4<f32>, BATCH>;
var<workgroup> done_count: atomic<u32>;
var<workgroup> done_snapshot: u32;

@compute @workgroup_size(SUB, SUB, 1)
fn rasterize(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(local_invocation_id) lid: vec3<u32>,
    @builtin(local_invocation_index) tid: u32,
) {
    let image = wid.z;
    let tile = (image * params.tiles_y + wid.y / PER_TILE) * params.tiles_x + wid.x / PER_TILE;
    let px = wid.x * SUB + lid.x;
    let py = wid.y * SUB + lid.y;
    let inside = px < params.width && py < params.height;
    let centre = vec2<f32>(f32(px) + 0.5, f32(py) + 0.5);
    let range = ranges[tile];
    let pix = (image * params.height + py) * params.width + px;
    // Chunks of `chunk` Gaussians (the backward's split); no boundary when unsplit.
    let chunk = max(params.min_chunk, (range.y - range.x + params.splits - 1u) / params.splits);
    var boundary = 0xffffffffu;
    if (SPLIT && inside) {
        boundary = range.x + chunk;
    }
    var slot = 0u;

    if (tid == 0u) {
        atomicStore(&done_count, 0u);
    }
    workgroupBarrier();
    var done = !inside;
    if (done) {
        atomicAdd(&done_count, 1u);
    }
    var t = 1.0;
    var color = vec3<f32>(0.0);
    var depth = 0.0;
    var last = range.x;
    let num_batches = (range.y - range.x + BATCH - 1u) / BATCH;
    for (var b = 0u; b < num_batches; b++) {
        // Everyone must be done reading the previous batch before it is overwritten.
        workgroupBarrier();
        if (tid == 0u) {
            done_snapshot = atomicLoad(&done_count);
        }
        if (workgroupUniformLoad(&done_snapshot) == BATCH) {
            break;
        }
        let start = range.x + b * BATCH;
        if (start + tid < range.y) {
            let g = tile_values[start + tid];
            batch_a[tid] = projected[3u * g];
            batch_b[tid] = projected[3u * g + 1u];
            batch_c[tid] = projected[3u * g + 2u];
        }
        workgroupBarrier();
        let n = min(BATCH, range.y - start);
        for (var j = 0u; j < n && !done; j++) {
            if (SPLIT && start + j == boundary) {
                chunk_state[slot * params.pixels + pix] = vec4<f32>(color, t);
                chunk_depth[slot * params.pixels + pix] = depth;
                slot += 1u;
                boundary += chunk;
            }
            let a = batch_a[j];
            let conic = batch_b[j].xyz;
            let d = a.xy - centre;
            let power = -0.5 * (conic.x * d.x * d.x + conic.z * d.y * d.y) - conic.y * d.x * d.y;
            if (power > 0.0) {
                continue;
            }
            let alpha = min(ALPHA_MAX, a.w * exp(power));
            if (alpha < ALPHA_MIN) {
                continue;
            }
            let next_t = t * (1.0 - alpha);
            if (next_t < T_MIN) {
                done = true;
                atomicAdd(&done_count, 1u);
                break;
            }
            let w = alpha * t;
            color += batch_c[j].xyz * w;
            depth += a.z * w;
            t = next_t;
            last = start + j + 1u;
        }
    }
    if (inside) {
        if (SPLIT) {
            let last_slot = (params.splits - 1u) * params.pixels + pix;
            chunk_state[last_slot] = vec4<f32>(color, t);
            chunk_depth[last_slot] = depth;
        }
        out_rgba[pix] = vec4<f32>(color + t * backgrounds[image].xyz, 1.0 - t);
        out_depth[pix] = depth;
        out_t[pix] = t;
        out_last[pix] = last;
    }
}
