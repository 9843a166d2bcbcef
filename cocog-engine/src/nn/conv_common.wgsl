// What conv.wgsl's head kernels and conv_first.wgsl's first-layer weight gradient share: their
// uniform (composite.rs's ConvU), their weight gradients' per-range partial sums, and the
// fixed-order sum of one weight's ranges.

struct Conv {
    images: u32,
    cin: u32,
    cout: u32,
    k: u32,
    height: u32,
    width: u32,
    // Offsets into the parameter buffer; bias_off = 0xffffffff for none.
    w_off: u32,
    bias_off: u32,
    pad: u32,
    // The weight gradient's split: (image, pixel) positions per range, and ranges.
    per_part: u32,
    parts: u32,
    // The chunk's first render in the buffers that hold every render (the head's logits and
    // their gradient, the first layer's renders); the chunk's own maps start at its first.
    image0: u32,
}

@group(0) @binding(0) var<uniform> cv: Conv;

// [range][weight]: each weight's sum over one range of pixels, `stride` weights per range.
@group(0) @binding(7) var<storage, read_write> partials: array<f32>;

var<workgroup> sums: array<f32, 256>;

// Weight t's partial sums over every range, added by the whole workgroup in a fixed order (a
// strided sum per invocation, then a tree), returned to every invocation. Call it in uniform
// control flow.
fn ranges_total(lid: u32, t: u32, stride: u32) -> f32 {
    var s = 0.0;
    for (var r = lid; r < cv.parts; r += 256u) {
        s += partials[r * stride + t];
    }
    sums[lid] = s;
    for (var w = 128u; w > 0u; w >>= 1u) {
        workgroupBarrier();
        if lid < w {
            sums[lid] += sums[lid + w];
        }
    }
    workgroupBarrier();
    return sums[0];
}
