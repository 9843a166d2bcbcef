// The uniform of conv.wgsl's head kernels and conv_first.wgsl's first-layer weight gradient
// (composite.rs's ConvU), declared once for both.

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
