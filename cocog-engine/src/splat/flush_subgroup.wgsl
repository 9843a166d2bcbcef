fn walk_end(last: u32) -> u32 {
    return subgroupMax(last);
}

fn flush(base: u32, contributes: bool, g0: vec4<f32>, g1: vec4<f32>, g2: vec2<f32>, lane: u32) {
    if (subgroupAny(contributes)) {
        let s0 = subgroupAdd(g0);
        let s1 = subgroupAdd(g1);
        let s2 = subgroupAdd(g2);
        if (lane == 0u) {
            add_grad(base, s0.x);
            add_grad(base + 1u, s0.y);
            add_grad(base + 2u, s0.z);
            add_grad(base + 3u, s0.w);
            add_grad(base + 4u, s1.x);
            add_grad(base + 5u, s1.y);
            add_grad(base + 6u, s1.z);
            add_grad(base + 7u, s1.w);
            add_grad(base + 8u, s2.x);
            if (DEPTH_GRAD) {
                add_grad(base + 9u, s2.y);
            }
        }
    }
}
