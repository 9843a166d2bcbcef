// Training loss (1 − λ)·L1 + λ·(1 − SSIM) over a batch of rgba images (alpha ignored) and
// its gradient. SSIM statistics come from a separable, zero-padded 11-tap Gaussian blur of
// (x, y, x², y², xy); the gradient blurs the per-pixel partials (A, B, C) once more, since
// the symmetric window makes the blur its own adjoint:
//   ∂SSIM/∂x = G∗A + 2x·(G∗B) + y·(G∗C).
//
// The scratch planes cover `rows` image rows from `row0` (possibly outside the image) of
// `num_images` images: all rows of all images at once, or, where that would exceed a buffer
// binding, one band of one image with a 10-row halo each side (the two stacked blurs each
// reach 5 rows). Rows of the scratch outside the image stay zero; only rows `out0..out1`
// count towards the loss and get a gradient.

struct Params {
    width: u32,
    height: u32,
    num_images: u32,
    // vec4 planes per pixel in `src`/`dst` for the generic blurs.
    count: u32,
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
@group(0) @binding(3) var<storage, read> src: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read_write> dst: array<vec4<f32>>;
@group(0) @binding(5) var<storage, read_write> partials: array<vec4<f32>>;

const C1: f32 = 0.0001;
const C2: f32 = 0.0009;
const RADIUS: i32 = 5;

var<workgroup> reduce: array<vec4<f32>, 256>;

fn tap(i: i32) -> f32 {
    let k = u32(i + RADIUS);
    return params.weights[k / 4u][k % 4u];
}

fn pixel_id(gid: vec3<u32>, nwg: vec3<u32>) -> u32 {
    return gid.x + gid.y * nwg.x * 256u;
}

fn num_pixels() -> u32 {
    return params.width * params.rows * params.num_images;
}

// Row of scratch pixel `s` within the scratch, and within its image.
fn local_row(s: u32) -> i32 {
    return i32((s / params.width) % params.rows);
}

fn image_row(s: u32) -> i32 {
    return params.row0 + local_row(s);
}

fn in_image(s: u32) -> bool {
    let r = image_row(s);
    return r >= 0 && r < i32(params.height);
}

fn counted(s: u32) -> bool {
    let r = image_row(s);
    return r >= params.out0 && r < params.out1 && r < i32(params.height);
}

// Index in `pred`, `gt` and the gradient of scratch pixel `s` (a row inside the image).
fn image_pixel(s: u32) -> u32 {
    let image = s / (params.width * params.rows);
    return params.pixel0 + (image * params.height + u32(image_row(s))) * params.width
        + s % params.width;
}

@compute @workgroup_size(256)
fn moments_h(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let pix = pixel_id(gid, nwg);
    if (pix >= num_pixels()) {
        return;
    }
    var m: array<vec3<f32>, 5>;
    if (!in_image(pix)) {
        for (var k = 0u; k < 5u; k++) {
            dst[5u * pix + k] = vec4<f32>(0.0);
        }
        return;
    }
    let x0 = i32(pix % params.width);
    let row = image_pixel(pix) - u32(x0);
    for (var i = -RADIUS; i <= RADIUS; i++) {
        let x = x0 + i;
        if (x < 0 || x >= i32(params.width)) {
            continue;
        }
        let w = tap(i);
        let a = pred[row + u32(x)].xyz;
        let b = gt[row + u32(x)].xyz;
        m[0] += w * a;
        m[1] += w * b;
        m[2] += w * a * a;
        m[3] += w * b * b;
        m[4] += w * a * b;
    }
    for (var k = 0u; k < 5u; k++) {
        dst[5u * pix + k] = vec4<f32>(m[k], 0.0);
    }
}

// Zero padding at the image's edges (`pos` of `extent`); taps that would leave the scratch
// (`local` of `local_extent`, a band's halo) are skipped: those rows are not used.
fn blur(pix: u32, step: i32, pos: i32, extent: i32, local: i32, local_extent: i32) {
    for (var k = 0u; k < params.count; k++) {
        var acc = vec4<f32>(0.0);
        for (var i = -RADIUS; i <= RADIUS; i++) {
            let p = pos + i;
            let l = local + i;
            if (p >= 0 && p < extent && l >= 0 && l < local_extent) {
                acc += tap(i) * src[u32(i32(pix) + i * step) * params.count + k];
            }
        }
        dst[pix * params.count + k] = acc;
    }
}

@compute @workgroup_size(256)
fn blur_h(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let pix = pixel_id(gid, nwg);
    if (pix < num_pixels()) {
        let x = i32(pix % params.width);
        blur(pix, 1, x, i32(params.width), x, i32(params.width));
    }
}

@compute @workgroup_size(256)
fn blur_v(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let pix = pixel_id(gid, nwg);
    if (pix < num_pixels()) {
        blur(pix, i32(params.width), image_row(pix), i32(params.height), local_row(pix),
            i32(params.rows));
    }
}

@compute @workgroup_size(256)
fn ssim_terms(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) tid: u32,
    @builtin(workgroup_id) wid: vec3<u32>,
) {
    let pix = pixel_id(gid, nwg);
    // (L1, SSIM, squared error of the prediction clamped to [0, 1] as a saved image is —
    // what PSNR needs —, 0), summed over channels.
    var sums = vec4<f32>(0.0);
    if (pix < num_pixels() && !in_image(pix)) {
        for (var k = 0u; k < 3u; k++) {
            dst[3u * pix + k] = vec4<f32>(0.0);
        }
    } else if (pix < num_pixels()) {
        let mx = src[5u * pix].xyz;
        let my = src[5u * pix + 1u].xyz;
        let vx = src[5u * pix + 2u].xyz - mx * mx;
        let vy = src[5u * pix + 3u].xyz - my * my;
        let cxy = src[5u * pix + 4u].xyz - mx * my;
        let n1 = 2.0 * mx * my + C1;
        let n2 = 2.0 * cxy + C2;
        let d1 = mx * mx + my * my + C1;
        let d2 = vx + vy + C2;
        let s = n1 * n2 / (d1 * d2);
        // Partials in (μx, σx², σxy), re-expressed in (μx, E[x²], E[xy]).
        let s_mu = 2.0 * my * n2 / (d1 * d2) - s * 2.0 * mx / d1;
        let s_var = -s / d2;
        let s_cov = 2.0 * n1 / (d1 * d2);
        dst[3u * pix] = vec4<f32>(s_mu - 2.0 * mx * s_var - my * s_cov, 0.0);
        dst[3u * pix + 1u] = vec4<f32>(s_var, 0.0);
        dst[3u * pix + 2u] = vec4<f32>(s_cov, 0.0);
        if (counted(pix)) {
            let at = image_pixel(pix);
            let diff = abs(pred[at].xyz - gt[at].xyz);
            let e = clamp(pred[at].xyz, vec3<f32>(0.0), vec3<f32>(1.0)) - gt[at].xyz;
            sums = vec4<f32>(diff.x + diff.y + diff.z, s.x + s.y + s.z, dot(e, e), 0.0);
        }
    }
    reduce[tid] = sums;
    workgroupBarrier();
    for (var off = 128u; off > 0u; off >>= 1u) {
        if (tid < off) {
            reduce[tid] += reduce[tid + off];
        }
        workgroupBarrier();
    }
    if (tid == 0u) {
        partials[params.partial0 + wid.x + wid.y * nwg.x] = reduce[0];
    }
}

@compute @workgroup_size(256)
fn ssim_grad(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let pix = pixel_id(gid, nwg);
    if (pix >= num_pixels() || !counted(pix)) {
        return;
    }
    let at = image_pixel(pix);
    let x = pred[at].xyz;
    let y = gt[at].xyz;
    let d_ssim = src[3u * pix].xyz + 2.0 * x * src[3u * pix + 1u].xyz + y * src[3u * pix + 2u].xyz;
    let l1 = sign(x - y);
    dst[at] = vec4<f32>(((1.0 - params.lambda) * l1 - params.lambda * d_ssim) * params.inv_n, 0.0);
}
