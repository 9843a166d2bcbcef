// Whether a Gaussian can reach alpha ≥ 1/255 at any pixel centre of a tile. Compositing
// skips weaker contributions, so leaving such tiles out of the key list changes no pixel
// while cutting the intersections that sorting and both rasterizers walk.
// `threshold` = ln(255·opacity): alpha ≥ 1/255 ⇔ ½·dᵀ·conic·d ≤ threshold.

const TILE_TEST_MARGIN: f32 = 1e-3;
const TILE_SIDE: f32 = 16.0;

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
    let lo = vec2<f32>(tile) * TILE_SIDE + 0.5 - mean;
    let hi = lo + (TILE_SIDE - 1.0);
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

// Column `v` (already rounded) clamped into [lo_x, hi_x), or `fallback` where it is not finite.
fn span_column(v: f32, lo_x: u32, hi_x: u32, fallback: u32) -> u32 {
    if (!finite(v)) {
        return fallback;
    }
    return u32(clamp(v, f32(lo_x), f32(hi_x - 1u)));
}

// The columns [first, end) of tile row `ty`, within the rectangle's [lo_x, hi_x), from the first
// to the last tile that `tile_hits` passes (first == end: none). project.wgsl counts a
// Gaussian's tiles with it and tiles.wgsl emits them, so both agree by construction.
//
// The tiles a Gaussian reaches in a row are contiguous: the form's minimum over the row's band
// of pixel centres is convex in x. So instead of testing every tile of a wide rectangle, the
// row is seeded at the tile holding the band's minimum, the span's ends are guessed from the
// ellipse's extent in the band, and each guess is walked to where `tile_hits` changes: a few
// tests per row, however wide, and the tiles a full scan would pass (a guess that rounding puts
// off costs steps, not tiles).
//
// Rows at most SCAN_WIDTH tiles wide are scanned tile by tile. renderer.rs prepends it, and
// TILE_SPANS, which has the two kernels take rows as spans at all (else they test every tile).
fn row_span(mean: vec2<f32>, conic: vec3<f32>, threshold: f32, ty: u32, lo_x: u32, hi_x: u32) -> vec2<u32> {
    if (hi_x - lo_x <= SCAN_WIDTH) {
        var first = hi_x;
        var end = hi_x;
        for (var x = lo_x; x < hi_x; x++) {
            if (tile_hits(mean, conic, threshold, vec2<u32>(x, ty))) {
                first = min(first, x);
                end = x + 1u;
            }
        }
        return vec2<u32>(first, end);
    }
    let h = span_seed(mean, conic, threshold, ty, lo_x, hi_x);
    if (h == NO_SEED) {
        return vec2<u32>(lo_x, lo_x);
    }
    let guess = span_guess(mean, conic, threshold, ty, lo_x, hi_x, h);
    return walk_span(mean, conic, threshold, ty, lo_x, hi_x, h, guess.x, guess.y);
}

// Guesses of the first and last column of the span through seed h: where the ellipse reaches
// in the band, or h itself where the form is too close to singular to say.
fn span_guess(mean: vec2<f32>, conic: vec3<f32>, threshold: f32, ty: u32, lo_x: u32, hi_x: u32, h: u32) -> vec2<u32> {
    let a = conic.x;
    let b = conic.y;
    let c = conic.z;
    let y0 = f32(ty) * TILE_SIDE + 0.5 - mean.y;
    let y1 = y0 + TILE_SIDE - 1.0;
    // The ellipse ½q ≤ threshold (with tile_hits' margin) spans x in [l, r] over the band: at
    // height y its chord is (−b·y ± √(a·t − det·y²)) / a, reaching furthest right at
    // y = −b·√(t / (c·det)) and left at +b·√(t / (c·det)), or at the band's nearer edge.
    var first = h;
    var last = h;
    let det = fma(a, c, -b * b);
    let t = 2.0 * (threshold + TILE_TEST_MARGIN * (1.0 + threshold));
    if (det > 0.0) {
        let reach = sqrt(a * t / det);
        let lo = max(y0, -reach);
        let hi = min(y1, reach);
        if (lo <= hi) {
            let k = sqrt(t / (c * det));
            let yr = clamp(-b * k, lo, hi);
            let yl = clamp(b * k, lo, hi);
            let r = (-b * yr + sqrt(max(a * t - det * yr * yr, 0.0))) / a;
            let l = (-b * yl - sqrt(max(a * t - det * yl * yl, 0.0))) / a;
            // Column x's centres span [16·x + 0.5, 16·x + 15.5] − mean.x.
            last = span_column(floor((r + mean.x - 0.5) / TILE_SIDE), lo_x, hi_x, h);
            first = span_column(ceil((l + mean.x - 15.5) / TILE_SIDE), lo_x, hi_x, h);
        }
    }
    return vec2<u32>(first, last);
}

const NO_SEED: u32 = 0xffffffffu;

// A column of row `ty` that `tile_hits` passes if any does (NO_SEED where none does): the one
// holding the x where the form is least over the band (the mean's own row if the band holds it,
// else its nearer edge), or the next, where that x falls in the gap between two columns'
// pixel centres; the rectangle's nearer end where it lies outside.
fn span_seed(mean: vec2<f32>, conic: vec3<f32>, threshold: f32, ty: u32, lo_x: u32, hi_x: u32) -> u32 {
    let y0 = f32(ty) * TILE_SIDE + 0.5 - mean.y;
    let dy = clamp(0.0, y0, y0 + TILE_SIDE - 1.0);
    // Offset x lies in column floor((x + mean.x − 0.5) / 16), or in the gap after it.
    let at = span_column(floor((-conic.y * dy / conic.x + mean.x - 0.5) / TILE_SIDE), lo_x, hi_x, lo_x);
    if (tile_hits(mean, conic, threshold, vec2<u32>(at, ty))) {
        return at;
    }
    let next = min(at + 1u, hi_x - 1u);
    if (next != at && tile_hits(mean, conic, threshold, vec2<u32>(next, ty))) {
        return next;
    }
    return NO_SEED;
}

// The span through seed column h (which passes) from guesses of its ends, each walked to where
// `tile_hits` changes; a guess on the wrong side of h counts as h.
fn walk_span(mean: vec2<f32>, conic: vec3<f32>, threshold: f32, ty: u32, lo_x: u32, hi_x: u32, h: u32, first_guess: u32, last_guess: u32) -> vec2<u32> {
    var last = max(last_guess, h);
    if (tile_hits(mean, conic, threshold, vec2<u32>(last, ty))) {
        while (last + 1u < hi_x && tile_hits(mean, conic, threshold, vec2<u32>(last + 1u, ty))) {
            last++;
        }
    } else if (last > h) {
        // h passes, so this stops at h at the latest.
        last--;
        while (last > h && !tile_hits(mean, conic, threshold, vec2<u32>(last, ty))) {
            last--;
        }
    }
    var first = min(first_guess, h);
    if (tile_hits(mean, conic, threshold, vec2<u32>(first, ty))) {
        while (first > lo_x && tile_hits(mean, conic, threshold, vec2<u32>(first - 1u, ty))) {
            first--;
        }
    } else if (first < h) {
        first++;
        while (first < h && !tile_hits(mean, conic, threshold, vec2<u32>(first, ty))) {
            first++;
        }
    }
    return vec2<u32>(first, last + 1u);
}
