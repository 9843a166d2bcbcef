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

fn sh_basis_grad(d: vec3<f32>, k: u32) -> vec3<f32> {
    let x = d.x;
    let y = d.y;
    let z = d.z;
    switch k {
        case 1u: { return vec3<f32>(0.0, -SH_C1, 0.0); }
        case 2u: { return vec3<f32>(0.0, 0.0, SH_C1); }
        case 3u: { return vec3<f32>(-SH_C1, 0.0, 0.0); }
        case 4u: { return SH_C2[0] * vec3<f32>(y, x, 0.0); }
        case 5u: { return SH_C2[1] * vec3<f32>(0.0, z, y); }
        case 6u: { return SH_C2[2] * vec3<f32>(-2.0 * x, -2.0 * y, 4.0 * z); }
        case 7u: { return SH_C2[3] * vec3<f32>(z, 0.0, x); }
        case 8u: { return SH_C2[4] * vec3<f32>(2.0 * x, -2.0 * y, 0.0); }
        case 9u: { return SH_C3[0] * vec3<f32>(6.0 * x * y, 3.0 * x * x - 3.0 * y * y, 0.0); }
        case 10u: { return SH_C3[1] * vec3<f32>(y * z, x * z, x * y); }
        case 11u: { return SH_C3[2] * vec3<f32>(-2.0 * x * y, 4.0 * z * z - x * x - 3.0 * y * y, 8.0 * y * z); }
        case 12u: { return SH_C3[3] * vec3<f32>(-6.0 * x * z, -6.0 * y * z, 6.0 * z * z - 3.0 * x * x - 3.0 * y * y); }
        case 13u: { return SH_C3[4] * vec3<f32>(4.0 * z * z - 3.0 * x * x - y * y, -2.0 * x * y, 8.0 * x * z); }
        case 14u: { return SH_C3[5] * vec3<f32>(2.0 * x * z, -2.0 * y * z, x * x - y * y); }
        case 15u: { return SH_C3[6] * vec3<f32>(3.0 * x * x - 3.0 * y * y, -6.0 * x * y, 0.0); }
        default: { return vec3<f32>(0.0); }
    }
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
    let basis = sh_basis(f.dir, n);
    let v_pre = select(vec3<f32>(0.0), v_color, f.color_pre > vec3<f32>(0.0));
    let base = g * 3u * n;
    let row = shared_row(g) * 3u * n;
    var v_dir = vec3<f32>(0.0);
    for (var k = 0u; k < n; k++) {
        v_sh[base + k] = v_pre.x * basis[k];
        v_sh[base + n + k] = v_pre.y * basis[k];
        v_sh[base + 2u * n + k] = v_pre.z * basis[k];
        let coeff = vec3<f32>(sh[row + k], sh[row + n + k], sh[row + 2u * n + k]);
        v_dir += dot(v_pre, coeff) * sh_basis_grad(f.dir, k);
    }
    v_p += (v_dir - f.dir * dot(f.dir, v_dir)) / f.dist;
    for (var k = 0u; k < 3u; k++) {
        v_means[3u * g + k] = v_p[k];
    }
    v_opacity_logits[g] = v_opacity * f.opacity * (1.0 - f.opacity);
}
