// Training loss (1 − λ)·L1 + λ·(1 − SSIM) over a batch of rgba images (alpha ignored) and its
// gradient, in two fused passes over 16×8 tiles of pixels. SSIM's statistics are a separable,
// zero-padded 11-tap Gaussian blur of (x, y, x², y², xy); the gradient blurs the per-pixel
// partials (A, B, C) once more, since the symmetric window makes the blur its own adjoint:
//   ∂SSIM/∂x = G∗A + 2x·(G∗B) + y·(G∗C).
// ssim_forward blurs a tile's moments (with its 5-row halo) along rows into workgroup memory,
// then along columns, and writes (A, B, C) and the loss's sums; ssim_backward blurs (A, B, C)
// the same way and writes the gradient. SSIM needs E[x²] and E[y²] only as their sum, so the
// forward keeps four moments per channel, and a 16×8 tile's twelve (or the backward's nine)
// fit the 16 KiB of workgroup memory every adapter has: one barrier between the two blurs.
//
// The terms scratch covers `rows` image rows from `row0` of `num_images` images: every row the
// gradient of a scored row (`out0..out1`) reads, i.e. 5 beyond them each side within the image.
// Where the scratch of a whole batch would exceed a buffer binding, the host runs one band of
// one image at a time.

struct Params {
    width: u32,
    height: u32,
    num_images: u32,
    pad: u32,
    lambda: f32,
    inv_n: f32,
    row0: i32,
    rows: u32,
    out0: i32,
    out1: i32,
    // Pixel offset of the (first) image in `pred`, `gt` and the gradient.
    pixel0: u32,
    // First slot of this dispatch's workgroup sums in `partials`.
    partial0: u32,
    weights: array<vec4<f32>, 3>,
}

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> pred: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> gt: array<vec4<f32>>;
// Per scratch pixel: A, B, C (xyz: the channels).
@group(0) @binding(3) var<storage, read_write> terms: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read_write> v_pred: array<vec4<f32>>;
@group(0) @binding(5) var<storage, read_write> partials: array<vec4<f32>>;

const C1: f32 = 0.0001;
const C2: f32 = 0.0009;
const RADIUS: i32 = 5;
// A tile: TW columns × TH rows, one thread per pixel; its rows with the halo.
const TW: u32 = 16u;
const TH: u32 = 8u;
const HR: u32 = 18u;
// Row-blurred values per channel and (halo row, column): the forward's four moments, the
// backward's three terms.
const HALF: u32 = 288u;

// forward: [channel][moment][halo row][column], then the loss sums' reduction.
// backward: [channel][term][halo row][column].
var<workgroup> wa: array<f32, 3456>;

fn tap(i: i32) -> f32 {
    let k = u32(i + RADIUS);
    return params.weights[k / 4u][k % 4u];
}

fn in_image(r: i32, c: i32) -> bool {
    return r >= 0 && c >= 0 && r < i32(params.height) && c < i32(params.width);
}

fn scored(r: i32) -> bool {
    return r >= params.out0 && r < params.out1 && r < i32(params.height);
}

// Index in `pred`, `gt` and the gradient of image b's pixel (r, c).
fn image_pixel(b: u32, r: i32, c: i32) -> u32 {
    return params.pixel0 + (b * params.height + u32(r)) * params.width + u32(c);
}

// Index of the terms of image b's pixel (r, c), a row of the scratch.
fn scratch_pixel(b: u32, r: i32, c: i32) -> u32 {
    return (b * params.rows + u32(r - params.row0)) * params.width + u32(c);
}

fn in_scratch(r: i32) -> bool {
    return r >= params.row0 && r < params.row0 + i32(params.rows);
}

@compute @workgroup_size(16, 8)
fn ssim_forward(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_id) l: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let b = wg.z;
    let c0 = i32(wg.x * TW);
    let r0 = params.row0 + i32(wg.y * TH);
    let col = c0 + i32(l.x);
    let row = r0 + i32(l.y);
    // Along rows: (μx, μy, E[x² + y²], E[xy]) per channel at each halo row and column.
    for (var e = lid; e < HALF; e += TW * TH) {
        let r = r0 - RADIUS + i32(e / TW);
        let c = c0 + i32(e % TW);
        var mx = vec3<f32>(0.0);
        var my = vec3<f32>(0.0);
        var sq = vec3<f32>(0.0);
        var xy = vec3<f32>(0.0);
        if r >= 0 && r < i32(params.height) {
            for (var i = -RADIUS; i <= RADIUS; i++) {
                if in_image(r, c + i) {
                    let at = image_pixel(b, r, c + i);
                    let x = pred[at].xyz;
                    let y = gt[at].xyz;
                    let w = tap(i);
                    mx += w * x;
                    my += w * y;
                    sq += w * (x * x + y * y);
                    xy += w * x * y;
                }
            }
        }
        for (var k = 0u; k < 3u; k++) {
            let base = 4u * k * HALF + e;
            wa[base] = mx[k];
            wa[base + HALF] = my[k];
            wa[base + 2u * HALF] = sq[k];
            wa[base + 3u * HALF] = xy[k];
        }
    }
    workgroupBarrier();
    // Along columns, then SSIM and its partials in (μx, σx², σxy), re-expressed in
    // (μx, E[x²], E[xy]).
    var ssim = vec3<f32>(0.0);
    var s_mu = vec3<f32>(0.0);
    var s_var = vec3<f32>(0.0);
    var s_cov = vec3<f32>(0.0);
    for (var k = 0u; k < 3u; k++) {
        var m = vec4<f32>(0.0);
        for (var j = 0u; j < 11u; j++) {
            let at = 4u * k * HALF + (l.y + j) * TW + l.x;
            m += tap(i32(j) - RADIUS)
                * vec4<f32>(wa[at], wa[at + HALF], wa[at + 2u * HALF], wa[at + 3u * HALF]);
        }
        let mx = m.x;
        let my = m.y;
        let cxy = m.w - mx * my;
        let n1 = 2.0 * mx * my + C1;
        let n2 = 2.0 * cxy + C2;
        let d1 = mx * mx + my * my + C1;
        let d2 = m.z - mx * mx - my * my + C2;
        let s = n1 * n2 / (d1 * d2);
        ssim[k] = s;
        let p_mu = 2.0 * my * n2 / (d1 * d2) - s * 2.0 * mx / d1;
        let p_var = -s / d2;
        let p_cov = 2.0 * n1 / (d1 * d2);
        s_mu[k] = p_mu - 2.0 * mx * p_var - my * p_cov;
        s_var[k] = p_var;
        s_cov[k] = p_cov;
    }
    // (L1, SSIM, squared error of the prediction clamped to [0, 1] as a saved image is — what
    // PSNR needs —, 0), summed over channels.
    var sums = vec4<f32>(0.0);
    if in_image(row, col) && in_scratch(row) {
        let t = 3u * scratch_pixel(b, row, col);
        terms[t] = vec4<f32>(s_mu, 0.0);
        terms[t + 1u] = vec4<f32>(s_var, 0.0);
        terms[t + 2u] = vec4<f32>(s_cov, 0.0);
        if scored(row) {
            let at = image_pixel(b, row, col);
            let diff = abs(pred[at].xyz - gt[at].xyz);
            let e = clamp(pred[at].xyz, vec3<f32>(0.0), vec3<f32>(1.0)) - gt[at].xyz;
            sums = vec4<f32>(diff.x + diff.y + diff.z, ssim.x + ssim.y + ssim.z, dot(e, e), 0.0);
        }
    }
    // The tile's sums: 16 threads add 8 each, then one adds those 16, in a fixed order.
    workgroupBarrier();
    for (var q = 0u; q < 4u; q++) {
        wa[q * 128u + lid] = sums[q];
    }
    workgroupBarrier();
    if lid < 16u {
        var part = vec4<f32>(0.0);
        for (var i = 0u; i < 8u; i++) {
            let at = lid * 8u + i;
            part += vec4<f32>(wa[at], wa[128u + at], wa[256u + at], wa[384u + at]);
        }
        for (var q = 0u; q < 4u; q++) {
            wa[512u + q * 16u + lid] = part[q];
        }
    }
    workgroupBarrier();
    if lid == 0u {
        var total = vec4<f32>(0.0);
        for (var i = 0u; i < 16u; i++) {
            total += vec4<f32>(wa[512u + i], wa[528u + i], wa[544u + i], wa[560u + i]);
        }
        let slot = wg.x + nwg.x * (wg.y + nwg.y * wg.z);
        partials[params.partial0 + slot] = total;
    }
}

// Tiles over the scored rows.
@compute @workgroup_size(16, 8)
fn ssim_backward(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(local_invocation_id) l: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let b = wg.z;
    let c0 = i32(wg.x * TW);
    let r0 = params.out0 + i32(wg.y * TH);
    let col = c0 + i32(l.x);
    let row = r0 + i32(l.y);
    for (var e = lid; e < HALF; e += TW * TH) {
        let r = r0 - RADIUS + i32(e / TW);
        let c = c0 + i32(e % TW);
        var g0 = vec3<f32>(0.0);
        var g1 = vec3<f32>(0.0);
        var g2 = vec3<f32>(0.0);
        if r >= 0 && r < i32(params.height) && in_scratch(r) {
            for (var i = -RADIUS; i <= RADIUS; i++) {
                if in_image(r, c + i) {
                    let t = 3u * scratch_pixel(b, r, c + i);
                    let w = tap(i);
                    g0 += w * terms[t].xyz;
                    g1 += w * terms[t + 1u].xyz;
                    g2 += w * terms[t + 2u].xyz;
                }
            }
        }
        for (var k = 0u; k < 3u; k++) {
            let base = 3u * k * HALF + e;
            wa[base] = g0[k];
            wa[base + HALF] = g1[k];
            wa[base + 2u * HALF] = g2[k];
        }
    }
    workgroupBarrier();
    if !in_image(row, col) || !scored(row) {
        return;
    }
    let at = image_pixel(b, row, col);
    let x = pred[at].xyz;
    let y = gt[at].xyz;
    var d_ssim = vec3<f32>(0.0);
    for (var k = 0u; k < 3u; k++) {
        var g = vec3<f32>(0.0);
        for (var j = 0u; j < 11u; j++) {
            let t = 3u * k * HALF + (l.y + j) * TW + l.x;
            g += tap(i32(j) - RADIUS) * vec3<f32>(wa[t], wa[t + HALF], wa[t + 2u * HALF]);
        }
        d_ssim[k] = g.x + 2.0 * x[k] * g.y + y[k] * g.z;
    }
    let l1 = sign(x - y);
    v_pred[at] = vec4<f32>(((1.0 - params.lambda) * l1 - params.lambda * d_ssim) * params.inv_n, 0.0);
}
