// Whether a Gaussian can reach alpha ≥ 1/255 at any pixel centre of a tile. Compositing
// skips weaker contributions, so leaving such tiles out of the key list changes no pixel
// while cutting the intersections that sorting and both rasterizers walk.
// `threshold` = ln(255·opacity): alpha ≥ 1/255 ⇔ ½·dᵀ·conic·d ≤ threshold.

const TILE_TEST_MARGIN: f32 = 1e-3;

fn quad_form(conic: vec3<f32>, d: vec2<f32>) -> f32 {
    return conic.x * d.x * d.x + 2.0 * conic.y * d.x * d.y + conic.z * d.y * d.y;
}

// Minimum of the convex quadratic along an edge where one offset is fixed.
fn edge_min(fixed: f32, lo: f32, hi: f32, a_fixed: f32, b: f32, c_free: f32) -> f32 {
    let free = clamp(-b * fixed / c_free, lo, hi);
    return a_fixed * fixed * fixed + 2.0 * b * fixed * free + c_free * free * free;
}

fn tile_hits(mean: vec2<f32>, conic: vec3<f32>, threshold: f32, tile: vec2<u32>) -> bool {
    // Offsets (pixel centre − mean) spanned by the tile's pixel centres.
    let lo = vec2<f32>(tile) * 16.0 + 0.5 - mean;
    let hi = lo + 15.0;
    var q = 0.0;
    if (lo.x > 0.0 || hi.x < 0.0 || lo.y > 0.0 || hi.y < 0.0) {
        // The mean is outside: the convex form's minimum over the rectangle is on an edge.
        q = min(
            min(edge_min(lo.x, lo.y, hi.y, conic.x, conic.y, conic.z), edge_min(hi.x, lo.y, hi.y, conic.x, conic.y, conic.z)),
            min(edge_min(lo.y, lo.x, hi.x, conic.z, conic.y, conic.x), edge_min(hi.y, lo.x, hi.x, conic.z, conic.y, conic.x)),
        );
    }
    return 0.5 * q <= threshold + TILE_TEST_MARGIN * (1.0 + threshold);
}
