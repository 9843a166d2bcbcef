// A training step on a frame too large for one buffer binding runs band by band; these
// kernels gather what the bands produce into what one pass over the frame would have (the
// parameters' gradients are summed by the engine's AddInto).

struct Sizes {
    // Gaussians.
    count: u32,
    pad0: u32,
    pad1: u32,
    pad2: u32,
}

@group(0) @binding(0) var<uniform> sizes: Sizes;
// A band's projected records (12 floats a Gaussian, [7] the radius, 0 when culled) and their
// gradients (10 floats, [0..2] the mean2d's), and the frame's gathered ones.
@group(0) @binding(3) var<storage, read> projected: array<f32>;
@group(0) @binding(4) var<storage, read> v_projected: array<f32>;
@group(0) @binding(5) var<storage, read_write> frame_projected: array<f32>;
@group(0) @binding(6) var<storage, read_write> frame_v_projected: array<f32>;
// A band's renderer status [overflowed, intersections needed] and the frame's.
@group(0) @binding(7) var<storage, read> status: array<u32>;
@group(0) @binding(8) var<storage, read_write> frame_status: array<u32>;

fn index(wg: vec3<u32>, nwg: vec3<u32>, lid: u32) -> u32 {
    return (wg.y * nwg.x + wg.x) * 256u + lid;
}

// What densification's statistics read: visible in the frame when visible in a band (any
// radius > 0), and the frame's mean2d gradient, the sum of the bands'.
@compute @workgroup_size(256)
fn merge_pass(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let i = index(wg, nwg, lid);
    if i >= sizes.count {
        return;
    }
    frame_projected[12u * i + 7u] = max(frame_projected[12u * i + 7u], projected[12u * i + 7u]);
    frame_v_projected[10u * i] += v_projected[10u * i];
    frame_v_projected[10u * i + 1u] += v_projected[10u * i + 1u];
}

// Overflowed when a band did; the room the largest band needs.
@compute @workgroup_size(1)
fn merge_status() {
    frame_status[0] = max(frame_status[0], status[0]);
    frame_status[1] = max(frame_status[1], status[1]);
}
