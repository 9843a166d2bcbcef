@group(0) @binding(9) var<storage, read_write> v_proj: array<atomic<f32>>;

fn add_grad(i: u32, v: f32) {
    atomicAdd(&v_proj[i], v);
}
