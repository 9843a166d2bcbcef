//! F's convolutions as implicit matrix products (the im2col matrix is gathered while a tile
//! loads, never stored): the forward, the gradient of the input, and the weight and bias
//! gradients, which sum over every pixel of every render with split K. Maps are
//! [image][channel][y][x]; the first layer reads the renders' rgba [image][y][x][4].
//!
//! Parameters shared by the three (u0…u7): width, height, the other side's channel count (cin
//! for the forward and weight gradient, cout for the input gradient), kernel size, weight
//! offset, bias offset (`NO_BIAS` for none), 1 for an rgba input, and the first image's index
//! in an input that holds every render (`MapSize::image0`).
//!
//! Element types: the forward writes a stored map (`map_t`, see precision.rs); the input is
//! `in_t`, the renders' f32 for the 5×5 layer and a stored map for the 3×3 ones; gradients are
//! f32.

use super::precision::MapPrecision;
use crate::core::{Bind, GpuContext, Recorder, Workspace};
use crate::prims::{CoopBlock, Gemm, GemmLayout, GemmShape, GemmTile, OperandScales};

pub const NO_BIAS: u32 = u32::MAX;

const COMMON: &str = "
fn conv_width() -> u32 { return gemm.u0; }
fn conv_height() -> u32 { return gemm.u1; }
fn conv_ksize() -> u32 { return KS; }
fn conv_pixels() -> u32 { return gemm.u0 * gemm.u1; }
// (row, column) of pixel p moved by ±(kernel tap r − pad); may fall outside the map.
fn tap(p: u32, r: u32, sign: i32) -> vec2<i32> {
    let yx = divmod(p, conv_width());
    let k = vec2<u32>(r / KS, r % KS);
    let pad = i32(conv_ksize() / 2u);
    return vec2<i32>(i32(yx.x) + sign * (i32(k.x) - pad), i32(yx.y) + sign * (i32(k.y) - pad));
}
fn inside(at: vec2<i32>) -> bool {
    return at.x >= 0 && at.y >= 0 && at.x < i32(conv_height()) && at.y < i32(conv_width());
}
fn offset(at: vec2<i32>) -> u32 {
    return u32(at.x) * conv_width() + u32(at.y);
}
// Image b's value of input channel c at pixel q (rgba renders or [channel][pixel] maps).
fn input_at(b: u32, c: u32, q: u32) -> f32 {
    let i = b + gemm.u7;
    if gemm.u6 == 1u {
        return f32(input[(i * conv_pixels() + q) * 4u + c]);
    }
    return f32(input[(i * gemm.u2 + c) * conv_pixels() + q]);
}
";

/// out[b][co][p] = bias[co] + Σ_{ci,ky,kx} W[co][ci][ky][kx]·in[b][ci][p + (ky, kx) − pad],
/// one batch per image. M = cout, N = pixels, K = cin × k².
const FORWARD: &str = "
@group(0) @binding(2) var<storage, read> params: array<f32>;
@group(0) @binding(3) var<storage, read> input: array<in_t>;
@group(0) @binding(4) var<storage, read_write> output: array<map_t>;
fn load_a(b: u32, m: u32, k: u32) -> f32 { return params[gemm.u4 + m * gemm.k + k]; }
fn load_b(b: u32, k: u32, n: u32) -> f32 {
    let c = vec2<u32>(k / (KS * KS), k % (KS * KS));
    let at = tap(n, c.y, 1);
    if !inside(at) { return 0.0; }
    return input_at(b, c.x, offset(at));
}
fn epilogue(b: u32, m: u32, n: u32, v: f32) {
    var bias = 0.0;
    if gemm.u5 != 0xffffffffu { bias = params[gemm.u5 + m]; }
    output[(b * gemm.m + m) * conv_pixels() + n] = to_map(v + bias);
}
";

/// v_in[b][ci][p] = Σ_{co,ky,kx} W[co][ci][ky][kx]·v_out[b][co][p − (ky, kx) + pad].
/// M = cin, N = pixels, K = cout × k².
const INPUT_GRAD: &str = "
@group(0) @binding(2) var<storage, read> params: array<f32>;
@group(0) @binding(3) var<storage, read> v_out: array<f32>;
@group(0) @binding(4) var<storage, read_write> v_in: array<f32>;
// input_at refers to it; no loader here calls it, so it is never bound.
@group(0) @binding(5) var<storage, read> input: array<in_t>;
fn load_a(b: u32, m: u32, k: u32) -> f32 {
    let c = vec2<u32>(k / (KS * KS), k % (KS * KS));
    return params[gemm.u4 + (c.x * gemm.m + m) * KS * KS + c.y];
}
fn load_b(b: u32, k: u32, n: u32) -> f32 {
    let c = vec2<u32>(k / (KS * KS), k % (KS * KS));
    let at = tap(n, c.y, -1);
    if !inside(at) { return 0.0; }
    return v_out[((b + gemm.u7) * gemm.u2 + c.x) * conv_pixels() + offset(at)];
}
fn epilogue(b: u32, m: u32, n: u32, v: f32) {
    v_in[(b * gemm.m + m) * conv_pixels() + n] = v;
}
";

/// ∂W[co][ci][ky][kx] = Σ_{b,p} v_out[b][co][p]·in[b][ci][p + (ky, kx) − pad], and the bias as
/// a column of ones; summed over every image (batch) and pixel. M = cout, N = cin × k² (+1),
/// K = pixels.
const WEIGHT_GRAD: &str = "
@group(0) @binding(2) var<storage, read> input: array<in_t>;
@group(0) @binding(3) var<storage, read> v_out: array<f32>;
@group(0) @binding(4) var<storage, read_write> v_params: array<f32>;
fn taps() -> u32 { return gemm.u2 * conv_ksize() * conv_ksize(); }
fn load_a(b: u32, m: u32, k: u32) -> f32 {
    return v_out[(b * gemm.m + m) * conv_pixels() + k];
}
fn load_b(b: u32, k: u32, n: u32) -> f32 {
    if n == taps() { return 1.0; }
    let c = vec2<u32>(n / (KS * KS), n % (KS * KS));
    let at = tap(k, c.y, 1);
    if !inside(at) { return 0.0; }
    return input_at(b, c.x, offset(at));
}
fn epilogue(b: u32, m: u32, n: u32, v: f32) {
    if n == taps() {
        v_params[gemm.u5 + m] = v;
    } else {
        v_params[gemm.u4 + m * taps() + n] = v;
    }
}
";

/// One convolution layer's geometry: (cin, cout, kernel size, weight offset, bias offset).
pub type ConvLayer = (u32, u32, u32, u32, u32);

/// The compiled products of one kernel size.
#[derive(Debug)]
struct ConvKernels {
    forward: Gemm,
    /// None for the 5×5 layer: F reads detached renders, so nothing needs their gradient.
    input_grad: Option<Gemm>,
    weight_grad: Gemm,
}

/// The compiled implicit-GEMM convolutions for one channel count: F's 5×5 and 3×3 layers.
#[derive(Debug)]
pub struct ConvGemm {
    k3: ConvKernels,
    k5: ConvKernels,
}

/// Maps of `images` renders of `width`×`height`: a chunk of a view's renders when F's maps of
/// all of them would outgrow a binding. `image0` is the chunk's first render in the buffers
/// that hold every render (the renders, the logits and their gradient); the chunk's own maps
/// start at its first render, so they are read with `image0` 0.
#[derive(Clone, Copy, Debug)]
pub struct MapSize {
    pub width: u32,
    pub height: u32,
    pub images: u32,
    pub image0: u32,
}

fn shape(
    m: u32,
    n: u32,
    k: u32,
    size: MapSize,
    other: u32,
    layer: ConvLayer,
    rgba: bool,
) -> GemmShape {
    let (_, _, ks, w_off, bias) = layer;
    GemmShape {
        m,
        n,
        k,
        batches: size.images,
        params: [
            size.width,
            size.height,
            other,
            ks,
            w_off,
            bias,
            u32::from(rgba),
            size.image0,
            0,
            0,
        ],
    }
}

/// One product of a layer: its label, WGSL problem, layout, and operand scales on tensor cores.
struct Problem {
    label: String,
    source: String,
    layout: GemmLayout,
    scales: OperandScales,
}

/// A layer's forward, input gradient and weight gradient as problems. `cin` is the input channel
/// count of the layer with this kernel size (its weight gradient's width), `input` the element
/// type of its input.
fn problems(
    channels: u32,
    ks: u32,
    cin: u32,
    precision: MapPrecision,
    input: &str,
) -> [Problem; 3] {
    // Per pixel the forward and input gradient are `channels` wide; the weight gradient is
    // channels × (taps + bias).
    let maps = GemmTile::for_shape(channels, 1 << 16);
    let weights = GemmTile::for_shape(channels, cin * ks * ks + 1);
    let problem = |label: &str, body: &str, (a_k_fast, b_k_fast, split_k), scales| Problem {
        label: format!("{label} {ks}×{ks}"),
        source: format!(
            "{}alias in_t = {input};\nconst KS: u32 = {ks}u;\n{COMMON}{body}",
            precision.prelude()
        ),
        layout: GemmLayout {
            a_k_fast,
            b_k_fast,
            split_k,
            ones_column: false,
            tile: if split_k { weights } else { maps },
        },
        scales,
    };
    // On tensor cores the loss gradient (v_out) is scaled into f16's normal range: spread over
    // every pixel it lies near 1e-7..1e-5, and 2^16 puts it near 1e-2..1 (it must stay below 1).
    const GRADIENT: f32 = 65536.0;
    [
        problem(
            "conv forward",
            FORWARD,
            (true, false, false),
            OperandScales::NONE,
        ),
        problem(
            "conv input grad",
            INPUT_GRAD,
            (true, false, false),
            OperandScales {
                a: 1.0,
                b: GRADIENT,
            },
        ),
        problem(
            "conv weight grad",
            WEIGHT_GRAD,
            (true, true, true),
            OperandScales {
                a: GRADIENT,
                b: 1.0,
            },
        ),
    ]
}

impl ConvKernels {
    /// With `cooperative`, on tensor cores where the context enabled them; the input
    /// gradient only `with_input_grad`.
    fn new(
        ctx: &GpuContext,
        problems: [Problem; 3],
        cooperative: bool,
        with_input_grad: bool,
    ) -> Self {
        let compile = |p: &Problem| {
            cooperative
                .then(|| Gemm::cooperative(ctx, &p.label, &p.source, p.layout, p.scales))
                .flatten()
                .unwrap_or_else(|| Gemm::new(ctx, &p.label, &p.source, p.layout))
        };
        let [forward, input_grad, weight_grad] = &problems;
        Self {
            forward: compile(forward),
            input_grad: with_input_grad.then(|| compile(input_grad)),
            weight_grad: compile(weight_grad),
        }
    }
}

impl ConvGemm {
    /// Kernels tiled for layers of `channels` outputs (and inputs, for the input gradient):
    /// the 5×5 layer reads the renders, the 3×3 ones F's stored maps.
    /// With `cooperative`, the products run on tensor cores where the context enabled them
    /// (`Gemm::cooperative`; experimental, f16 operands).
    pub fn new(
        ctx: &GpuContext,
        channels: u32,
        precision: MapPrecision,
        cooperative: bool,
    ) -> Self {
        let kernels = |ks, cin, input, with_input_grad| {
            ConvKernels::new(
                ctx,
                problems(channels, ks, cin, precision, input),
                cooperative,
                with_input_grad,
            )
        };
        Self {
            k3: kernels(3, channels, "map_t", true),
            k5: kernels(5, 3, "f32", false),
        }
    }

    /// The tensor-core block layout the 3×3 products run in (None: the f32 tiles).
    pub fn coop_block(&self) -> Option<CoopBlock> {
        self.k3.forward.coop_block()
    }

    fn kernels(&self, layer: ConvLayer) -> &ConvKernels {
        if layer.2 == 5 { &self.k5 } else { &self.k3 }
    }

    pub fn forward(
        &self,
        rec: &mut Recorder,
        ws: &mut Workspace,
        layer: ConvLayer,
        size: MapSize,
        params: &dyn Bind,
        input: &dyn Bind,
        output: &dyn Bind,
        rgba: bool,
    ) {
        let (cin, cout, ks, _, _) = layer;
        let s = shape(
            cout,
            size.width * size.height,
            cin * ks * ks,
            size,
            cin,
            layer,
            rgba,
        );
        self.kernels(layer)
            .forward
            .encode(rec, ws, s, &[(2, params), (3, input), (4, output)]);
    }

    pub fn input_grad(
        &self,
        rec: &mut Recorder,
        ws: &mut Workspace,
        layer: ConvLayer,
        size: MapSize,
        params: &dyn Bind,
        v_out: &dyn Bind,
        v_in: &dyn Bind,
    ) {
        let (cin, cout, ks, _, _) = layer;
        let s = shape(
            cin,
            size.width * size.height,
            cout * ks * ks,
            size,
            cout,
            layer,
            false,
        );
        self.kernels(layer)
            .input_grad
            .as_ref()
            .expect("only the 3×3 layers' input gradients are compiled: F's input is detached")
            .encode(rec, ws, s, &[(2, params), (3, v_out), (4, v_in)]);
    }

    pub fn weight_grad(
        &self,
        rec: &mut Recorder,
        ws: &mut Workspace,
        layer: ConvLayer,
        size: MapSize,
        input: &dyn Bind,
        v_out: &dyn Bind,
        v_params: &dyn Bind,
        rgba: bool,
    ) {
        let (cin, cout, ks, _, bias) = layer;
        let columns = cin * ks * ks + u32::from(bias != NO_BIAS);
        let s = shape(
            cout,
            columns,
            size.width * size.height,
            size,
            cin,
            layer,
            rgba,
        );
        self.kernels(layer).weight_grad.encode(
            rec,
            ws,
            s,
            &[(2, input), (3, v_out), (4, v_params)],
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every convolution product compiles for cooperative matrices (naga to SPIR-V, as wgpu
    /// does on Vulkan) at both map precisions, on NVIDIA's fragments and lavapipe's: CI's
    /// adapter has none to run them.
    #[test]
    fn every_product_compiles_on_cooperative_matrices() {
        let nvidia = crate::CoopFragments {
            side: 16,
            subgroup: 32,
        };
        let lavapipe = crate::CoopFragments {
            side: 8,
            subgroup: 8,
        };
        for (fragments, precision) in [
            (nvidia, MapPrecision::F32),
            (nvidia, MapPrecision::F16),
            (lavapipe, MapPrecision::F16),
        ] {
            for (ks, cin, input) in [(3, 64, "map_t"), (5, 3, "f32")] {
                for p in problems(64, ks, cin, precision, input) {
                    for (name, block) in crate::CoopBlock::NAMED {
                        let what = format!("{} ({precision:?}, block {name})", p.label);
                        // As `shader` hands it to wgpu: enables first.
                        let source = crate::core::hoist_enables(&Gemm::cooperative_source(
                            &p.source, p.layout, p.scales, fragments, block,
                        ));
                        let module = naga::front::wgsl::parse_str(&source)
                            .unwrap_or_else(|e| panic!("{what}: {}", e.emit_to_string(&source)));
                        let info = naga::valid::Validator::new(
                            naga::valid::ValidationFlags::all(),
                            naga::valid::Capabilities::all(),
                        )
                        .validate(&module)
                        .unwrap_or_else(|e| panic!("{what}: {e:?}"));
                        let options = naga::back::spv::Options {
                            lang_version: (1, 5),
                            ..Default::default()
                        };
                        naga::back::spv::write_vec(&module, &info, &options, None)
                            .unwrap_or_else(|e| panic!("{what}: {e}"));
                    }
                }
            }
        }
    }
}
