// The composite of the M + 1 renders: per pixel, softmax over the renders of F's logits (or
// equal weights before F starts) and the weighted sum; and its adjoint. F sees the renders
// detached, so the renders' gradient is only through the product. Renders and the blend are
// rgba [image][y][x][4]; logits and weights [image][y][x].

struct Blend {
    images: u32,
    pixels: u32,
    // 1: equal weights, the logits are not read.
    uniform_weights: u32,
    pad: u32,
}

@group(0) @binding(0) var<uniform> bl: Blend;
@group(0) @binding(1) var<storage, read> renders: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> logits: array<f32>;
@group(0) @binding(3) var<storage, read_write> weights: array<f32>;
@group(0) @binding(4) var<storage, read_write> blend: array<vec4<f32>>;
@group(0) @binding(5) var<storage, read> v_blend: array<vec4<f32>>;
@group(0) @binding(6) var<storage, read_write> v_renders: array<vec4<f32>>;
@group(0) @binding(7) var<storage, read_write> v_logits: array<f32>;

fn pixel(wg: vec3<u32>, nwg: vec3<u32>, lid: u32) -> u32 {
    return (wg.y * nwg.x + wg.x) * 256u + lid;
}

@compute @workgroup_size(256)
fn blend_forward(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let p = pixel(wg, nwg, lid);
    if p >= bl.pixels {
        return;
    }
    var top = -3.0e38;
    if bl.uniform_weights == 0u {
        for (var i = 0u; i < bl.images; i++) {
            top = max(top, logits[i * bl.pixels + p]);
        }
    }
    var sum = 0.0;
    for (var i = 0u; i < bl.images; i++) {
        var e = 1.0;
        if bl.uniform_weights == 0u {
            e = exp(logits[i * bl.pixels + p] - top);
        }
        weights[i * bl.pixels + p] = e;
        sum += e;
    }
    var out = vec4<f32>(0.0);
    for (var i = 0u; i < bl.images; i++) {
        let w = weights[i * bl.pixels + p] / sum;
        weights[i * bl.pixels + p] = w;
        out += w * renders[i * bl.pixels + p];
    }
    blend[p] = out;
}

@compute @workgroup_size(256)
fn blend_backward(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let p = pixel(wg, nwg, lid);
    if p >= bl.pixels {
        return;
    }
    let g = vec4<f32>(v_blend[p].xyz, 0.0);
    let b = blend[p];
    for (var i = 0u; i < bl.images; i++) {
        let w = weights[i * bl.pixels + p];
        let r = renders[i * bl.pixels + p];
        v_renders[i * bl.pixels + p] = w * g;
        v_logits[i * bl.pixels + p] = w * dot(r.xyz - b.xyz, g.xyz);
    }
}
