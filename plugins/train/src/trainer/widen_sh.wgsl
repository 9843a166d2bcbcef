// SH growth: every row's three channel blocks of `old_k` coefficients become blocks of
// `new_k`, the new coefficients zero (trainer.rs's `widen_sh` is the CPU model).

struct Params {
    rows: u32,
    old_k: u32,
    new_k: u32,
    pad: u32,
}

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> narrow: array<f32>;
@group(0) @binding(2) var<storage, read_write> wide: array<f32>;

@compute @workgroup_size(256)
fn widen_sh(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = gid.x + gid.y * nwg.x * 256u;
    if (i >= params.rows * 3u * params.new_k) {
        return;
    }
    // One block per (row, channel).
    let block = i / params.new_k;
    let k = i % params.new_k;
    wide[i] = select(0.0, narrow[block * params.old_k + min(k, params.old_k - 1u)], k < params.old_k);
}
