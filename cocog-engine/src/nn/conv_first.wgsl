// F's first layer, a zero-padded 5×5 convolution from a render's rgb to C channels: its weight
// and bias gradients. Renders are rgba [image][y][x][4] (f32); the gradient maps f32
// [image][channel][y][x].
// The uniform `cv`, `partials` and `ranges_total` are conv_common.wgsl's, prepended.

@group(0) @binding(1) var<storage, read> params: array<f32>;
@group(0) @binding(2) var<storage, read> renders: array<f32>;

// Inputs per pixel: 3 channels × 25 taps, in the weights' order [channel][ky][kx].
const INPUTS: u32 = 75u;

// ∂W[co][j] = Σ_p ∂z[co][p] · in_j(p) over every pixel p of the chunk's images, in_j the 75
// inputs of pixel p's 5×5 neighbourhood (and 1 for the bias, j = 75). A workgroup takes one
// range of pixels and a block of 64 output channels × 76 columns of the result, a 4 × 5 block
// per invocation in named vec4 accumulators (no local array, which NVIDIA's compiler may keep
// in memory), from slices of 16 pixels staged in workgroup memory: the gradient maps are read
// once. As an implicit GEMM with split K, 64 × 16 blocks read them five times over (2.2 ms at
// 400×300 on an H200; this kernel 0.77 + 0.04 ms for the sums). `first_weight_sum` then adds
// each weight's ranges in a fixed order.

@group(0) @binding(4) var<storage, read> v_out: array<f32>;
@group(0) @binding(6) var<storage, read_write> v_params: array<f32>;

// SLICE (pixels per staged slice) and COLUMNS (75 inputs and the bias) are prepended by
// composite.rs's FirstLayer; the columns are padded to 16 blocks of 5.
const PADDED: u32 = 80u;

// [pixel][output channel / 4] and [pixel][column].
var<workgroup> stage_a: array<vec4<f32>, 256>;
var<workgroup> stage_b: array<f32, 1280>;

// Input j of pixel q of the chunk (1 for the bias column, 0 past it).
fn input_of(q: u32, j: u32) -> f32 {
    if j >= COLUMNS {
        return 0.0;
    }
    if j == INPUTS {
        return 1.0;
    }
    let hw = cv.height * cv.width;
    let p = q % hw;
    let tap = j % 25u;
    let yy = i32(p / cv.width) + i32(tap / 5u) - 2;
    let xx = i32(p % cv.width) + i32(tap % 5u) - 2;
    if yy < 0 || xx < 0 || yy >= i32(cv.height) || xx >= i32(cv.width) {
        return 0.0;
    }
    let at = u32(yy) * cv.width + u32(xx);
    return renders[((q / hw + cv.image0) * hw + at) * 4u + j / 25u];
}

@compute @workgroup_size(256)
fn first_weight_part(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    // Grid: x ranges, z blocks of 64 output channels.
    let range = wg.x;
    let co0 = wg.z * 64u;
    let hw = cv.height * cv.width;
    let begin = range * cv.per_part;
    let end = min(begin + cv.per_part, cv.images * hw);
    // This invocation's output channels 4·tco.. and columns 5·tj.. .
    let tco = lid / 16u;
    let tj = lid % 16u;
    var acc0 = vec4<f32>(0.0);
    var acc1 = vec4<f32>(0.0);
    var acc2 = vec4<f32>(0.0);
    var acc3 = vec4<f32>(0.0);
    var acc4 = vec4<f32>(0.0);
    for (var s0 = begin; s0 < end; s0 += SLICE) {
        // 16 pixels × 64 channels, 16 consecutive pixels of one channel per 16 invocations.
        for (var r = 0u; r < 4u; r++) {
            let e = lid + 256u * r;
            let px = e % SLICE;
            let co = co0 + e / SLICE;
            let q = s0 + px;
            var v = 0.0;
            if q < end && co < cv.cout {
                v = v_out[((q / hw) * cv.cout + co) * hw + q % hw];
            }
            stage_a[px * 16u + (e / SLICE) / 4u][(e / SLICE) % 4u] = v;
        }
        for (var r = 0u; r < 5u; r++) {
            let e = lid + 256u * r;
            let px = e / PADDED;
            let q = s0 + px;
            var v = 0.0;
            if q < end {
                v = input_of(q, e % PADDED);
            }
            stage_b[e] = v;
        }
        workgroupBarrier();
        for (var px = 0u; px < SLICE; px++) {
            let a = stage_a[px * 16u + tco];
            let b = px * PADDED + 5u * tj;
            acc0 += a * stage_b[b];
            acc1 += a * stage_b[b + 1u];
            acc2 += a * stage_b[b + 2u];
            acc3 += a * stage_b[b + 3u];
            acc4 += a * stage_b[b + 4u];
        }
        workgroupBarrier();
    }
    let co = co0 + 4u * tco;
    store_partial(range, co, 5u * tj, acc0);
    store_partial(range, co, 5u * tj + 1u, acc1);
    store_partial(range, co, 5u * tj + 2u, acc2);
    store_partial(range, co, 5u * tj + 3u, acc3);
    store_partial(range, co, 5u * tj + 4u, acc4);
}

// Column j of output channels co.. co + 3 (those that exist) of one range's sums.
fn store_partial(range: u32, co: u32, j: u32, v: vec4<f32>) {
    if j >= COLUMNS {
        return;
    }
    for (var r = 0u; r < 4u; r++) {
        if co + r < cv.cout {
            partials[(range * cv.cout + co + r) * COLUMNS + j] = v[r];
        }
    }
}

// One workgroup per (output channel, column): its ranges added in a fixed order.
@compute @workgroup_size(256)
fn first_weight_sum(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let t = wg.y * nwg.x + wg.x;
    if t >= cv.cout * COLUMNS {
        return;
    }
    // Partials are [range][output channel][column].
    let total = ranges_total(lid, t, cv.cout * COLUMNS);
    if lid == 0u {
        let co = t / COLUMNS;
        let j = t % COLUMNS;
        if j == INPUTS {
            if cv.bias_off != 0xffffffffu {
                v_params[cv.bias_off + co] = total;
            }
        } else {
            v_params[cv.w_off + co * INPUTS + j] = total;
        }
    }
}
