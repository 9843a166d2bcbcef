//! F's 3×3 convolutions and their input gradients by Winograd's F(2×2, 3×3) (conv_winograd.wgsl):
//! 16 products per tile, output channel and summed channel where the direct convolution needs
//! 36, so 2.25× fewer multiply-adds for the layer that holds nearly all of F's arithmetic.

use super::conv_gemm::{ConvLayer, MapSize, NO_BIAS};
use super::precision::MapPrecision;
use crate::core::{Bind, GpuContext, Kernel, Recorder, Workspace, shader};

/// A workgroup's block of tiles per side and of output channels (conv_winograd.wgsl's BT, BM).
const BLOCK_TILES: u32 = 8;
const BLOCK_M: u32 = 64;
/// Positions of a transformed 4×4 tile.
const POSITIONS: u64 = 16;

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct WinoU {
    width: u32,
    height: u32,
    outputs: u32,
    summed: u32,
    w_off: u32,
    bias_off: u32,
    transposed: u32,
    image0: u32,
    tiles_x: u32,
    tiles_y: u32,
    pad: [u32; 2],
}

#[derive(Debug)]
struct Pass {
    weights: Kernel,
    conv: Kernel,
}

impl Pass {
    fn new(ctx: &GpuContext, precision: MapPrecision, input: &str, output: &str) -> Self {
        let label = format!("conv winograd {input}→{output}");
        let convert = if output == "map_t" { "to_map(v)" } else { "v" };
        let source = format!(
            "{}alias in_t = {input};\nalias out_t = {output};\n\
             fn to_out(v: f32) -> out_t {{ return {convert}; }}\n{}",
            precision.prelude(),
            include_str!("conv_winograd.wgsl")
        );
        let module = shader(ctx, &label, &source);
        Self {
            weights: Kernel::labelled(
                ctx,
                &module,
                "winograd_weights",
                &format!("{label} weights"),
            ),
            conv: Kernel::labelled(ctx, &module, "winograd_conv", &label),
        }
    }

    /// Transforms the kernel into a workspace buffer, then convolves `images` maps.
    fn run(
        &self,
        rec: &mut Recorder,
        ws: &mut Workspace,
        u: WinoU,
        images: u32,
        [params, input, output]: [&dyn Bind; 3],
    ) {
        let pairs = u.outputs * u.summed;
        let transformed = ws.buffer(
            rec.ctx(),
            "winograd weights",
            POSITIONS * u64::from(pairs) * 4,
        );
        let uniform = rec.uniform(&u);
        self.weights.dispatch_1d(
            rec,
            &[(0, &uniform), (1, params), (2, &transformed)],
            pairs.div_ceil(64),
        );
        let grid = [
            u.tiles_x.div_ceil(BLOCK_TILES),
            u.tiles_y.div_ceil(BLOCK_TILES) * u.outputs.div_ceil(BLOCK_M),
            images,
        ];
        self.conv.dispatch(
            rec,
            &[
                (0, &uniform),
                (1, params),
                (2, &transformed),
                (3, input),
                (4, output),
            ],
            grid,
        );
    }
}

/// The 3×3 layers' forward (stored maps in and out) and input gradient (f32 maps in and out).
#[derive(Debug)]
pub struct ConvWinograd {
    forward: Pass,
    grad: Pass,
}

impl ConvWinograd {
    /// Channels a pass should sum at least: one staged slice (conv_winograd.wgsl's BK).
    pub const MIN_SUMMED: u32 = 32;

    pub fn new(ctx: &GpuContext, precision: MapPrecision) -> Self {
        Self {
            forward: Pass::new(ctx, precision, "map_t", "map_t"),
            grad: Pass::new(ctx, precision, "f32", "f32"),
        }
    }

    fn uniform(layer: ConvLayer, size: MapSize, transposed: bool) -> WinoU {
        let (cin, cout, ks, w_off, bias_off) = layer;
        assert_eq!(ks, 3, "Winograd F(2×2, 3×3) runs 3×3 layers only");
        let (outputs, summed) = if transposed { (cin, cout) } else { (cout, cin) };
        WinoU {
            width: size.width,
            height: size.height,
            outputs,
            summed,
            w_off,
            bias_off: if transposed { NO_BIAS } else { bias_off },
            transposed: u32::from(transposed),
            image0: size.image0,
            tiles_x: size.width.div_ceil(2),
            tiles_y: size.height.div_ceil(2),
            pad: [0; 2],
        }
    }

    /// out = conv(input) + bias for a 3×3 `layer` over stored maps.
    #[allow(clippy::too_many_arguments)]
    pub fn forward(
        &self,
        rec: &mut Recorder,
        ws: &mut Workspace,
        layer: ConvLayer,
        size: MapSize,
        params: &dyn Bind,
        input: &dyn Bind,
        output: &dyn Bind,
    ) {
        let u = Self::uniform(layer, size, false);
        self.forward
            .run(rec, ws, u, size.images, [params, input, output]);
    }

    /// v_in = the gradient of a 3×3 `layer`'s input from its output's, `v_out`.
    #[allow(clippy::too_many_arguments)]
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
        let u = Self::uniform(layer, size, true);
        self.grad
            .run(rec, ws, u, size.images, [params, v_out, v_in]);
    }
}
