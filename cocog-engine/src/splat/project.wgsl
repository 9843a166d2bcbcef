// Projection forward: one thread per Gaussian (all images of the batch). Culled Gaussians
// get no tiles and the largest depth key, which the depth sort drops.

@group(0) @binding(7) var<storage, read_write> projected: array<vec4<f32>>;
@group(0) @binding(8) var<storage, read_write> rects: array<vec4<u32>>;
@group(0) @binding(9) var<storage, read_write> depth_keys: array<u32>;
@group(0) @binding(10) var<storage, read_write> ids: array<u32>;
@group(0) @binding(11) var<storage, read_write> counts: array<u32>;

@compute @workgroup_size(256)
fn project(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let g = gid.x + gid.y * nwg.x * 256u;
    if (g >= globals.num_gaussians) {
        return;
    }
    ids[g] = g;
    depth_keys[g] = 0xffffffffu;
    counts[g] = 0u;
    rects[g] = vec4<u32>(0u);
    let f = project_forward(g);
    if (!f.valid) {
        return;
    }
    let tiles = vec2<f32>(f32(globals.tiles_x), f32(globals.tiles_y));
    // Clamp in float before converting: out-of-range float→int conversions are not portable.
    let lo = vec2<u32>(clamp(floor((f.mean2d - f.radius) / TILE), vec2<f32>(0.0), tiles));
    let hi = vec2<u32>(clamp(ceil((f.mean2d + f.radius) / TILE), vec2<f32>(0.0), tiles));
    // Below 1/255 opacity no pixel can pass the compositing cut-off.
    let threshold = log(255.0 * f.opacity);
    if (lo.x >= hi.x || lo.y >= hi.y || !(threshold >= 0.0)) {
        return;
    }
    var count = 0u;
    for (var y = lo.y; y < hi.y; y++) {
        if (TILE_SPANS) {
            let span = row_span(f.mean2d, f.conic, threshold, y, lo.x, hi.x);
            count += span.y - span.x;
        } else {
            for (var x = lo.x; x < hi.x; x++) {
                count += u32(tile_hits(f.mean2d, f.conic, threshold, vec2<u32>(x, y)));
            }
        }
    }
    if (count == 0u) {
        return;
    }
    projected[3u * g] = vec4<f32>(f.mean2d, f.t.z, f.opacity);
    projected[3u * g + 1u] = vec4<f32>(f.conic, f.radius);
    projected[3u * g + 2u] = vec4<f32>(max(f.color_pre, vec3<f32>(0.0)), 0.0);
    rects[g] = vec4<u32>(lo.x | (lo.y << 16u), hi.x | (hi.y << 16u), f.image, 0u);
    depth_keys[g] = bitcast<u32>(f.t.z);
    counts[g] = count;
}
