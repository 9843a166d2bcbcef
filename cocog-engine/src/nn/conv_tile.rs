//! F's wide convolutions and their input gradients as spatially tiled kernels (conv_tile.wgsl):
//! the input patch of a block of pixels is staged once per slice of channels, where an im2col
//! GEMM gathers every tap of every pixel from global memory.

use super::conv_gemm::{ConvLayer, MapSize, NO_BIAS};
use super::precision::MapPrecision;
use crate::core::{Bind, GpuContext, Kernel, Recorder, shader};

/// A workgroup's block of pixels (conv_tile.wgsl's TW × TH) and of output channels.
const TILE_W: u32 = 16;
const TILE_H: u32 = 8;
const TILE_M: u32 = 64;

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct TileU {
    width: u32,
    height: u32,
    outputs: u32,
    summed: u32,
    w_off: u32,
    bias_off: u32,
    rgba_input: u32,
    transposed: u32,
    image0: u32,
    pad: [u32; 3],
}

/// The kernels per kernel size and direction: each reads and writes its own element types.
#[derive(Debug)]
pub struct ConvTile {
    /// 5×5, the renders (f32 rgba) into a stored map.
    first: Kernel,
    /// 3×3, a stored map into a stored map.
    forward3: Kernel,
    /// 3×3 transposed, an f32 gradient map into an f32 gradient map.
    grad3: Kernel,
}

impl ConvTile {
    pub fn new(ctx: &GpuContext, precision: MapPrecision) -> Self {
        // Channels per staged slice: the 5×5 slice's weights (64 × CC × 25 floats) and patch
        // must fit the 16 KiB of workgroup memory every adapter has.
        let kernel = |ks: u32, cc: u32, input: &str, output: &str| {
            let label = format!("conv tile {ks}×{ks} {input}→{output}");
            let convert = if output == "map_t" { "to_map(v)" } else { "v" };
            let source = format!(
                "{}alias in_t = {input};\nalias out_t = {output};\n\
                 fn to_out(v: f32) -> out_t {{ return {convert}; }}\n\
                 const KS: u32 = {ks}u;\nconst CC: u32 = {cc}u;\n{}",
                precision.prelude(),
                include_str!("conv_tile.wgsl")
            );
            Kernel::labelled(ctx, &shader(ctx, &label, &source), "conv_tile", &label)
        };
        Self {
            first: kernel(5, 2, "f32", "map_t"),
            forward3: kernel(3, 4, "map_t", "map_t"),
            grad3: kernel(3, 4, "f32", "f32"),
        }
    }

    fn dispatch(
        &self,
        rec: &mut Recorder,
        kernel: &Kernel,
        u: TileU,
        images: u32,
        bindings: [&dyn Bind; 3],
    ) {
        let uniform = rec.uniform(&u);
        let grid = [
            u.width.div_ceil(TILE_W),
            u.height.div_ceil(TILE_H) * u.outputs.div_ceil(TILE_M),
            images,
        ];
        let [params, input, output] = bindings;
        kernel.dispatch(
            rec,
            &[(0, &uniform), (1, params), (2, input), (3, output)],
            grid,
        );
    }

    /// out = conv(input) + bias for `layer` (in, out, kernel, weights, bias).
    pub fn forward(
        &self,
        rec: &mut Recorder,
        layer: ConvLayer,
        size: MapSize,
        params: &dyn Bind,
        input: &dyn Bind,
        output: &dyn Bind,
        rgba: bool,
    ) {
        let (cin, cout, ks, w_off, bias_off) = layer;
        let u = TileU {
            width: size.width,
            height: size.height,
            outputs: cout,
            summed: cin,
            w_off,
            bias_off,
            rgba_input: u32::from(rgba),
            transposed: 0,
            image0: size.image0,
            pad: [0; 3],
        };
        // F's first layer reads the renders, the rest F's stored maps.
        let kernel = if rgba { &self.first } else { &self.forward3 };
        assert_eq!(ks, if rgba { 5 } else { 3 }, "F's layer shapes");
        self.dispatch(rec, kernel, u, size.images, [params, input, output]);
    }

    /// v_in = the gradient of `layer`'s input from its output's, `v_out`.
    pub fn input_grad(
        &self,
        rec: &mut Recorder,
        layer: ConvLayer,
        size: MapSize,
        params: &dyn Bind,
        v_out: &dyn Bind,
        v_in: &dyn Bind,
    ) {
        let (cin, cout, ks, w_off, _) = layer;
        let u = TileU {
            width: size.width,
            height: size.height,
            outputs: cin,
            summed: cout,
            w_off,
            bias_off: NO_BIAS,
            rgba_input: 0,
            transposed: 1,
            image0: size.image0,
            pad: [0; 3],
        };
        // F's renders are detached: only its 3×3 layers take an input gradient.
        assert_eq!(ks, 3, "F's first layer has no input gradient");
        self.dispatch(rec, &self.grad3, u, size.images, [params, v_out, v_in]);
    }
}
