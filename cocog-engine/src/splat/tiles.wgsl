// Tile binning. After the Gaussians are sorted by depth (the culled ones dropped: only the first
// `visible[0]` sorted ids are real), `gather_counts` lays out their tile counts in depth order
// (zeros past the visible ones, and a trailing zero so the exclusive scan also yields the total),
// `emit_keys` writes one (tile, Gaussian) pair per covered tile — in depth order, so a
// stable sort on the tile alone leaves each tile's list front to back — and `tile_ranges`
// finds where each tile's run starts and ends in the sorted pairs.

struct Params {
    num_gaussians: u32,
    // Room in the key/value buffers; the count needed is offsets[num_gaussians].
    num_intersections: u32,
    tiles_x: u32,
    tiles_per_image: u32,
    // One past the last real tile: pads key slots the emission did not fill.
    sentinel_tile: u32,
    pad0: u32,
    pad1: u32,
    pad2: u32,
}

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> ids_sorted: array<u32>;
@group(0) @binding(2) var<storage, read> counts: array<u32>;
@group(0) @binding(3) var<storage, read_write> offsets: array<u32>;
@group(0) @binding(4) var<storage, read> rects: array<vec4<u32>>;
@group(0) @binding(5) var<storage, read_write> tile_keys: array<u32>;
@group(0) @binding(6) var<storage, read_write> tile_values: array<u32>;
@group(0) @binding(7) var<storage, read_write> ranges: array<vec2<u32>>;
@group(0) @binding(8) var<storage, read> projected: array<vec4<f32>>;
// [overflowed, intersections needed], read back asynchronously by training loops.
@group(0) @binding(9) var<storage, read_write> status: array<u32>;
// How many Gaussians the depth sort kept: those with at least one tile.
@group(0) @binding(10) var<storage, read> visible: array<u32>;

fn linear_id(gid: vec3<u32>, nwg: vec3<u32>) -> u32 {
    return gid.x + gid.y * nwg.x * 256u;
}

@compute @workgroup_size(256)
fn gather_counts(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let s = linear_id(gid, nwg);
    if (s < visible[0]) {
        offsets[s] = counts[ids_sorted[s]];
    } else if (s <= params.num_gaussians) {
        offsets[s] = 0u;
    }
}

@compute @workgroup_size(256)
fn emit_keys(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let s = linear_id(gid, nwg);
    if (s >= visible[0]) {
        return;
    }
    let g = ids_sorted[s];
    if (counts[g] == 0u) {
        return;
    }
    let r = rects[g];
    let lo = vec2<u32>(r.x & 0xffffu, r.x >> 16u);
    let hi = vec2<u32>(r.y & 0xffffu, r.y >> 16u);
    let base = r.z * params.tiles_per_image;
    let a = projected[3u * g];
    let conic = projected[3u * g + 1u].xyz;
    let threshold = log(255.0 * a.w);
    var out = offsets[s];
    // Past the capacity the pass is flagged as overflowed and redone; write nothing there.
    let stop = min(out + counts[g], params.num_intersections);
    for (var y = lo.y; y < hi.y; y++) {
        // The same tiles as the count in project.wgsl, so exactly counts[g] keys are written;
        // the bound and the padding below only guard against a compiler evaluating the two
        // copies differently, which would otherwise overwrite other Gaussians' keys.
        if (TILE_SPANS) {
            let span = row_span(a.xy, conic, threshold, y, lo.x, hi.x);
            for (var x = span.x; x < span.y && out < stop; x++) {
                tile_keys[out] = base + y * params.tiles_x + x;
                tile_values[out] = g;
                out++;
            }
        } else {
            for (var x = lo.x; x < hi.x && out < stop; x++) {
                if (tile_hits(a.xy, conic, threshold, vec2<u32>(x, y))) {
                    tile_keys[out] = base + y * params.tiles_x + x;
                    tile_values[out] = g;
                    out++;
                }
            }
        }
    }
    for (; out < stop; out++) {
        tile_keys[out] = params.sentinel_tile;
        tile_values[out] = g;
    }
}

@compute @workgroup_size(256)
fn tile_ranges(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = linear_id(gid, nwg);
    let n = min(offsets[params.num_gaussians], params.num_intersections);
    if (i >= n) {
        return;
    }
    let tile = tile_keys[i];
    if (i == 0u || tile_keys[i - 1u] != tile) {
        ranges[tile].x = i;
    }
    if (i + 1u == n || tile_keys[i + 1u] != tile) {
        ranges[tile].y = i + 1u;
    }
}

@compute @workgroup_size(1)
fn check_capacity() {
    let needed = offsets[params.num_gaussians];
    status[0] = u32(needed > params.num_intersections);
    status[1] = needed;
}
