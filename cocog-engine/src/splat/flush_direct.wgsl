const sg_lane: u32 = 0u;

fn add_nonzero(i: u32, v: f32) {
    if (v != 0.0) {
        add_grad(i, v);
    }
}

fn walk_end(last: u32) -> u32 {
    return last;
}

fn flush(base: u32, contributes: bool, g0: vec4<f32>, g1: vec4<f32>, g2: vec2<f32>, lane: u32) {
    if (contributes) {
        add_nonzero(base, g0.x);
        add_nonzero(base + 1u, g0.y);
        add_nonzero(base + 2u, g0.z);
        add_nonzero(base + 3u, g0.w);
        add_nonzero(base + 4u, g1.x);
        add_nonzero(base + 5u, g1.y);
        add_nonzero(base + 6u, g1.z);
        add_nonzero(base + 7u, g1.w);
        add_nonzero(base + 8u, g2.x);
        if (DEPTH_GRAD) {
            add_nonzero(base + 9u, g2.y);
        }
    }
}
