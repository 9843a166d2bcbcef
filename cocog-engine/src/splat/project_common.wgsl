// Shared by the projection forward and backward kernels: bindings of the Gaussian
// parameters and cameras, and the forward projection that both evaluate.

struct Globals {
    num_gaussians: u32,
    num_images: u32,
    width: u32,
    height: u32,
    tiles_x: u32,
    tiles_y: u32,
    sh_coeffs: u32,
    // 0, or the rows of opacity and SH that Gaussian g shares as row g mod shared_rows.
    shared_rows: u32,
}

struct ImageInfo {
    // Rows of camera_from_world; .w holds the translation.
    rot0: vec4<f32>,
    rot1: vec4<f32>,
    rot2: vec4<f32>,
    centre: vec4<f32>,
    // fx, fy, cx, cy
    intrinsics: vec4<f32>,
    background: vec4<f32>,
    first: u32,
    count: u32,
    // cy and height of the whole frame: a band of rows clamps against the frame's edges.
    frame_cy: f32,
    frame_height: f32,
}

@group(0) @binding(0) var<uniform> globals: Globals;
@group(0) @binding(1) var<storage, read> images: array<ImageInfo>;
@group(0) @binding(2) var<storage, read> means: array<f32>;
@group(0) @binding(3) var<storage, read> log_scales: array<f32>;
@group(0) @binding(4) var<storage, read> quats: array<vec4<f32>>;
@group(0) @binding(5) var<storage, read> opacity_logits: array<f32>;
@group(0) @binding(6) var<storage, read> sh: array<f32>;

const NEAR_PLANE: f32 = 0.01;
const LOW_PASS: f32 = 0.3;
const TILE: f32 = 16.0;
const SH_C0: f32 = 0.28209479177387814;
const SH_C1: f32 = 0.4886025119029199;
const SH_C2: array<f32, 5> = array<f32, 5>(1.0925484305920792, -1.0925484305920792, 0.31539156525252005, -1.0925484305920792, 0.5462742152960396);
const SH_C3: array<f32, 7> = array<f32, 7>(-0.5900435899266435, 2.890611442640554, -0.4570457994644658, 0.3731763325901154, -0.4570457994644658, 1.445305721320277, -0.5900435899266435);

fn finite3(v: vec3<f32>) -> bool {
    return finite(v.x) && finite(v.y) && finite(v.z);
}

fn shared_row(g: u32) -> u32 {
    if (globals.shared_rows == 0u) {
        return g;
    }
    return g % globals.shared_rows;
}

fn image_of(g: u32) -> u32 {
    for (var b = 0u; b < globals.num_images; b++) {
        let info = images[b];
        if (g >= info.first && g < info.first + info.count) {
            return b;
        }
    }
    return 0u;
}

// Coefficient k of the SH row at `row` (3 × n floats, channel-major), as rgb.
fn sh_coeff(row: u32, n: u32, k: u32) -> vec3<f32> {
    return vec3<f32>(sh[row + k], sh[row + n + k], sh[row + 2u * n + k]);
}

// The SH colour (with the +0.5 offset, before the clamp at 0) of the row at `row` towards unit
// direction d, written out term by term: an array of basis values indexed in a loop of runtime
// length would sit in local memory on GPUs. sh_backward (project_backward.wgsl) repeats the
// polynomials with their gradients: change both.
fn sh_color(d: vec3<f32>, row: u32, n: u32) -> vec3<f32> {
    let x = d.x;
    let y = d.y;
    let z = d.z;
    var c = vec3<f32>(0.5);
    c += SH_C0 * sh_coeff(row, n, 0u);
    if (n > 1u) {
        c += -SH_C1 * y * sh_coeff(row, n, 1u);
        c += SH_C1 * z * sh_coeff(row, n, 2u);
        c += -SH_C1 * x * sh_coeff(row, n, 3u);
    }
    if (n > 4u) {
        c += SH_C2[0] * x * y * sh_coeff(row, n, 4u);
        c += SH_C2[1] * y * z * sh_coeff(row, n, 5u);
        c += SH_C2[2] * (2.0 * z * z - x * x - y * y) * sh_coeff(row, n, 6u);
        c += SH_C2[3] * x * z * sh_coeff(row, n, 7u);
        c += SH_C2[4] * (x * x - y * y) * sh_coeff(row, n, 8u);
    }
    if (n > 9u) {
        c += SH_C3[0] * y * (3.0 * x * x - y * y) * sh_coeff(row, n, 9u);
        c += SH_C3[1] * x * y * z * sh_coeff(row, n, 10u);
        c += SH_C3[2] * y * (4.0 * z * z - x * x - y * y) * sh_coeff(row, n, 11u);
        c += SH_C3[3] * z * (2.0 * z * z - 3.0 * x * x - 3.0 * y * y) * sh_coeff(row, n, 12u);
        c += SH_C3[4] * x * (4.0 * z * z - x * x - y * y) * sh_coeff(row, n, 13u);
        c += SH_C3[5] * z * (x * x - y * y) * sh_coeff(row, n, 14u);
        c += SH_C3[6] * x * (x * x - 3.0 * y * y) * sh_coeff(row, n, 15u);
    }
    return c;
}

struct Fwd {
    valid: bool,
    image: u32,
    p: vec3<f32>,
    t: vec3<f32>,
    w: mat3x3<f32>,
    qn: vec4<f32>,
    qlen: f32,
    rot: mat3x3<f32>,
    s: vec3<f32>,
    cov3: mat3x3<f32>,
    jw: mat3x2<f32>,
    uc: f32,
    u_clamped: bool,
    vc: f32,
    v_clamped: bool,
    conic: vec3<f32>,
    mean2d: vec2<f32>,
    radius: f32,
    dir: vec3<f32>,
    dist: f32,
    color_pre: vec3<f32>,
    opacity: f32,
}

fn clamp_ratio(ratio: f32, lim_neg: f32, lim_pos: f32) -> vec2<f32> {
    // (value, 1 if clamped)
    if (ratio < -lim_neg) {
        return vec2<f32>(-lim_neg, 1.0);
    }
    if (ratio > lim_pos) {
        return vec2<f32>(lim_pos, 1.0);
    }
    return vec2<f32>(ratio, 0.0);
}

fn project_forward(g: u32) -> Fwd {
    var f: Fwd;
    f.valid = false;
    f.image = image_of(g);
    let info = images[f.image];
    let fx = info.intrinsics.x;
    let fy = info.intrinsics.y;
    let cx = info.intrinsics.z;
    let cy = info.intrinsics.w;
    f.p = vec3<f32>(means[3u * g], means[3u * g + 1u], means[3u * g + 2u]);
    f.w = transpose(mat3x3<f32>(info.rot0.xyz, info.rot1.xyz, info.rot2.xyz));
    f.t = f.w * f.p + vec3<f32>(info.rot0.w, info.rot1.w, info.rot2.w);
    if (!finite3(f.t) || f.t.z < NEAR_PLANE) {
        return f;
    }
    let q = quats[g];
    f.qlen = length(q);
    if (!finite(f.qlen) || f.qlen <= 1e-12) {
        return f;
    }
    f.qn = q / f.qlen;
    f.rot = quat_to_rot(f.qn);
    f.s = exp(vec3<f32>(log_scales[3u * g], log_scales[3u * g + 1u], log_scales[3u * g + 2u]));
    let m = f.rot * mat3x3<f32>(vec3<f32>(f.s.x, 0.0, 0.0), vec3<f32>(0.0, f.s.y, 0.0), vec3<f32>(0.0, 0.0, f.s.z));
    f.cov3 = m * transpose(m);
    let width = f32(globals.width);
    let height = info.frame_height;
    let fcy = info.frame_cy;
    let z = f.t.z;
    let uc = clamp_ratio(f.t.x / z, (cx + 0.3 * width) / fx, (width - cx + 0.3 * width) / fx);
    let vc = clamp_ratio(f.t.y / z, (fcy + 0.3 * height) / fy, (height - fcy + 0.3 * height) / fy);
    f.uc = uc.x;
    f.u_clamped = uc.y > 0.5;
    f.vc = vc.x;
    f.v_clamped = vc.y > 0.5;
    // J is 2×3: three columns of two rows.
    let jac = mat3x2<f32>(vec2<f32>(fx / z, 0.0), vec2<f32>(0.0, fy / z), vec2<f32>(-fx * f.uc / z, -fy * f.vc / z));
    f.jw = jac * f.w;
    let cov2 = f.jw * f.cov3 * transpose(f.jw);
    let a = cov2[0][0] + LOW_PASS;
    let b = cov2[1][0];
    let c = cov2[1][1] + LOW_PASS;
    let det = a * c - b * b;
    if (!finite(det) || det <= 0.0) {
        return f;
    }
    f.conic = vec3<f32>(c / det, -b / det, a / det);
    f.mean2d = vec2<f32>(fx * f.t.x / z + cx, fy * f.t.y / z + cy);
    let mid = 0.5 * (a + c);
    let lambda = mid + sqrt(max(0.1, mid * mid - det));
    f.radius = ceil(3.0 * sqrt(lambda));

    let dv = f.p - info.centre.xyz;
    f.dist = length(dv);
    f.dir = dv / f.dist;
    let n = globals.sh_coeffs;
    let color = sh_color(f.dir, shared_row(g) * 3u * n, n);
    f.color_pre = color;
    f.opacity = 1.0 / (1.0 + exp(-opacity_logits[shared_row(g)]));
    f.valid = finite3(f.conic) && finite(f.mean2d.x) && finite(f.mean2d.y) && finite3(color) && finite(f.opacity)
        && finite(f.radius) && finite(f.dist) && f.dist > 0.0;
    return f;
}
