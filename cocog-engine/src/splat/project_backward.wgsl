// Projection backward: one thread per Gaussian chains the screen-space gradients (v_proj)
// through EWA splatting, the quaternion normalisation, the scale activation, the sigmoid and
// the SH evaluation (including its view-direction dependence on the mean). Each Gaussian
// belongs to one image, so plain writes suffice; Gaussians sharing opacity and SH rows
// (`shared_row`) get a gradient row each, which the caller sums.

@group(0) @binding(7) var<storage, read> v_proj: array<f32>;
@group(0) @binding(8) var<storage, read_write> v_means: array<f32>;
@group(0) @binding(9) var<storage, read_write> v_log_scales: array<f32>;
@group(0) @binding(10) var<storage, read_write> v_quats: array<vec4<f32>>;
@group(0) @binding(11) var<storage, read_write> v_opacity_logits: array<f32>;
@group(0) @binding(12) var<storage, read_write> v_sh: array<f32>;

// Coefficient k's gradients, given its basis value b and the basis's gradient db in the
// direction: v_sh at `out` (the row's, as sh_coeff lays it out), and the return value, its share
// of the gradient of the view direction.
fn sh_term_backward(k: u32, b: f32, db: vec3<f32>, v_pre: vec3<f32>, out: u32, row: u32, n: u32) -> vec3<f32> {
    v_sh[out + k] = v_pre.x * b;
    v_sh[out + n + k] = v_pre.y * b;
    v_sh[out + 2u * n + k] = v_pre.z * b;
    return dot(v_pre, sh_coeff(row, n, k)) * db;
}

// sh_color's backward, term by term as it is: writes v_sh and returns the gradient of d.
fn sh_backward(d: vec3<f32>, v_pre: vec3<f32>, out: u32, row: u32, n: u32) -> vec3<f32> {
    let x = d.x;
    let y = d.y;
    let z = d.z;
    var v_d = sh_term_backward(0u, SH_C0, vec3<f32>(0.0), v_pre, out, row, n);
    if (n > 1u) {
        v_d += sh_term_backward(1u, -SH_C1 * y, vec3<f32>(0.0, -SH_C1, 0.0), v_pre, out, row, n);
        v_d += sh_term_backward(2u, SH_C1 * z, vec3<f32>(0.0, 0.0, SH_C1), v_pre, out, row, n);
        v_d += sh_term_backward(3u, -SH_C1 * x, vec3<f32>(-SH_C1, 0.0, 0.0), v_pre, out, row, n);
    }
    if (n > 4u) {
        v_d += sh_term_backward(4u, SH_C2[0] * x * y, SH_C2[0] * vec3<f32>(y, x, 0.0), v_pre, out, row, n);
        v_d += sh_term_backward(5u, SH_C2[1] * y * z, SH_C2[1] * vec3<f32>(0.0, z, y), v_pre, out, row, n);
        v_d += sh_term_backward(6u, SH_C2[2] * (2.0 * z * z - x * x - y * y),
            SH_C2[2] * vec3<f32>(-2.0 * x, -2.0 * y, 4.0 * z), v_pre, out, row, n);
        v_d += sh_term_backward(7u, SH_C2[3] * x * z, SH_C2[3] * vec3<f32>(z, 0.0, x), v_pre, out, row, n);
        v_d += sh_term_backward(8u, SH_C2[4] * (x * x - y * y),
            SH_C2[4] * vec3<f32>(2.0 * x, -2.0 * y, 0.0), v_pre, out, row, n);
    }
    if (n > 9u) {
        v_d += sh_term_backward(9u, SH_C3[0] * y * (3.0 * x * x - y * y),
            SH_C3[0] * vec3<f32>(6.0 * x * y, 3.0 * x * x - 3.0 * y * y, 0.0), v_pre, out, row, n);
        v_d += sh_term_backward(10u, SH_C3[1] * x * y * z,
            SH_C3[1] * vec3<f32>(y * z, x * z, x * y), v_pre, out, row, n);
        v_d += sh_term_backward(11u, SH_C3[2] * y * (4.0 * z * z - x * x - y * y),
            SH_C3[2] * vec3<f32>(-2.0 * x * y, 4.0 * z * z - x * x - 3.0 * y * y, 8.0 * y * z), v_pre, out, row, n);
        v_d += sh_term_backward(12u, SH_C3[3] * z * (2.0 * z * z - 3.0 * x * x - 3.0 * y * y),
            SH_C3[3] * vec3<f32>(-6.0 * x * z, -6.0 * y * z, 6.0 * z * z - 3.0 * x * x - 3.0 * y * y), v_pre, out, row, n);
        v_d += sh_term_backward(13u, SH_C3[4] * x * (4.0 * z * z - x * x - y * y),
            SH_C3[4] * vec3<f32>(4.0 * z * z - 3.0 * x * x - y * y, -2.0 * x * y, 8.0 * x * z), v_pre, out, row, n);
        v_d += sh_term_backward(14u, SH_C3[5] * z * (x * x - y * y),
            SH_C3[5] * vec3<f32>(2.0 * x * z, -2.0 * y * z, x * x - y * y), v_pre, out, row, n);
        v_d += sh_term_backward(15u, SH_C3[6] * x * (x * x - 3.0 * y * y),
            SH_C3[6] * vec3<f32>(3.0 * x * x - 3.0 * y * y, -6.0 * x * y, 0.0), v_pre, out, row, n);
    }
    return v_d;
}

fn write_zero(g: u32) {
    for (var k = 0u; k < 3u; k++) {
        v_means[3u * g + k] = 0.0;
        v_log_scales[3u * g + k] = 0.0;
    }
    v_quats[g] = vec4<f32>(0.0);
    v_opacity_logits[g] = 0.0;
    let n = 3u * globals.sh_coeffs;
    for (var k = 0u; k < n; k++) {
        v_sh[g * n + k] = 0.0;
    }
}

@compute @workgroup_size(256)
fn project_backward(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let g = gid.x + gid.y * nwg.x * 256u;
    if (g >= globals.num_gaussians) {
        return;
    }
    let f = project_forward(g);
    if (!f.valid) {
        // Culled or non-finite: no gradient, and no NaN leaking into the optimiser.
        write_zero(g);
        return;
    }
    let info = images[f.image];
    let fx = info.intrinsics.x;
    let fy = info.intrinsics.y;
    let vb = g * 10u;
    let v_mean2d = vec2<f32>(v_proj[vb], v_proj[vb + 1u]);
    let v_conic = vec3<f32>(v_proj[vb + 2u], v_proj[vb + 3u], v_proj[vb + 4u]);
    let v_color = vec3<f32>(v_proj[vb + 5u], v_proj[vb + 6u], v_proj[vb + 7u]);
    let v_opacity = v_proj[vb + 8u];
    let v_depth = v_proj[vb + 9u];
    let x = f.t.x;
    let y = f.t.y;
    let z = f.t.z;
    let z2 = z * z;
    var v_t = vec3<f32>(v_mean2d.x * fx / z, v_mean2d.y * fy / z, -v_mean2d.x * fx * x / z2 - v_mean2d.y * fy * y / z2 + v_depth);

    // conic = cov2⁻¹  ⇒  v_cov2 = -conic · V · conic (V: symmetric form of v_conic).
    let q2 = mat2x2<f32>(f.conic.x, f.conic.y, f.conic.y, f.conic.z);
    let vq = mat2x2<f32>(v_conic.x, 0.5 * v_conic.y, 0.5 * v_conic.y, v_conic.z);
    let v_cov2 = -1.0 * (q2 * vq * q2);
    let v_cov3 = transpose(f.jw) * v_cov2 * f.jw;
    let v_jw = 2.0 * (v_cov2 * f.jw * f.cov3);
    let v_j = v_jw * transpose(f.w);
    // mat3x2 indexing is [column][row]: J[r][c] = v_j[c][r].
    v_t.z += -fx / z2 * v_j[0][0] - fy / z2 * v_j[1][1];
    var du = fx * f.uc / z2;
    var dv = fy * f.vc / z2;
    if (!f.u_clamped) {
        du += fx * x / (z2 * z);
        v_t.x += -fx / z2 * v_j[2][0];
    }
    if (!f.v_clamped) {
        dv += fy * y / (z2 * z);
        v_t.y += -fy / z2 * v_j[2][1];
    }
    v_t.z += v_j[2][0] * du + v_j[2][1] * dv;
    var v_p = transpose(f.w) * v_t;

    // cov3 = M Mᵀ with M = R diag(s).
    let sm = mat3x3<f32>(vec3<f32>(f.s.x, 0.0, 0.0), vec3<f32>(0.0, f.s.y, 0.0), vec3<f32>(0.0, 0.0, f.s.z));
    let m = f.rot * sm;
    let v_m = 2.0 * (v_cov3 * m);
    for (var j = 0u; j < 3u; j++) {
        v_log_scales[3u * g + j] = dot(v_m[j], f.rot[j]) * f.s[j];
    }
    let vr_cols = v_m * sm;
    // vr(r, c) = d loss / d R[r][c].
    let v00 = vr_cols[0][0];
    let v01 = vr_cols[1][0];
    let v02 = vr_cols[2][0];
    let v10 = vr_cols[0][1];
    let v11 = vr_cols[1][1];
    let v12 = vr_cols[2][1];
    let v20 = vr_cols[0][2];
    let v21 = vr_cols[1][2];
    let v22 = vr_cols[2][2];
    let w = f.qn.x;
    let qx = f.qn.y;
    let qy = f.qn.z;
    let qz = f.qn.w;
    let v_qn = 2.0 * vec4<f32>(
        -qz * v01 + qy * v02 + qz * v10 - qx * v12 - qy * v20 + qx * v21,
        qy * v01 + qz * v02 + qy * v10 - 2.0 * qx * v11 - w * v12 + qz * v20 + w * v21 - 2.0 * qx * v22,
        -2.0 * qy * v00 + qx * v01 + w * v02 + qx * v10 + qz * v12 - w * v20 + qz * v21 - 2.0 * qy * v22,
        -2.0 * qz * v00 - w * v01 + qx * v02 + w * v10 - 2.0 * qz * v11 + qy * v12 + qx * v20 + qy * v21,
    );
    v_quats[g] = (v_qn - f.qn * dot(f.qn, v_qn)) / f.qlen;

    let n = globals.sh_coeffs;
    let v_pre = select(vec3<f32>(0.0), v_color, f.color_pre > vec3<f32>(0.0));
    let v_dir = sh_backward(f.dir, v_pre, g * 3u * n, shared_row(g) * 3u * n, n);
    v_p += (v_dir - f.dir * dot(f.dir, v_dir)) / f.dist;
    for (var k = 0u; k < 3u; k++) {
        v_means[3u * g + k] = v_p[k];
    }
    v_opacity_logits[g] = v_opacity * f.opacity * (1.0 - f.opacity);
}
