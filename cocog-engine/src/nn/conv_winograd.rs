//! F's 3×3 convolutions, their input gradients (conv_winograd.wgsl) and weight gradients
//! (conv_winograd_grad.wgsl) by Winograd's F(2×2, 3×3): 16 products per 2×2 output tile, output
//! channel and summed channel where the direct convolution needs 36, so 2.25× fewer
//! multiply-adds for the layer that holds nearly all of F's arithmetic.

use super::conv_gemm::{ConvLayer, MapSize, NO_BIAS};
use super::precision::MapPrecision;
use crate::core::{Bind, GpuContext, Kernel, Recorder, Workspace, shader};

/// A workgroup's block of tiles per side and of output channels (conv_winograd.wgsl's BT, BM).
const BLOCK_TILES: u32 = 8;
const BLOCK_M: u32 = 64;
/// Tiles per staged slice of the weight gradient (conv_winograd_grad.wgsl's BK), and about how
/// many ranges it sums apart.
const SLICE: u32 = 16;
const TARGET_PARTS: u32 = 128;
/// Channel pairs per workgroup of the sum, which conv_winograd_grad.wgsl is compiled with
/// (16 pairs × 16 positions make its 256 invocations).
const SUM_PAIRS: u32 = 16;
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
    images: u32,
    parts: u32,
    range: u32,
    pad: u32,
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
            concat!(
                include_str!("conv_winograd_common.wgsl"),
                include_str!("conv_winograd.wgsl")
            )
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

/// The weight gradient's two kernels (conv_winograd_grad.wgsl).
#[derive(Debug)]
struct WeightGrad {
    part: Kernel,
    sum: Kernel,
}

impl WeightGrad {
    fn new(ctx: &GpuContext, precision: MapPrecision) -> Self {
        let label = "conv winograd weight grad";
        let source = format!(
            "{}alias in_t = map_t;\nconst SUM_PAIRS: u32 = {SUM_PAIRS}u;\n{}",
            precision.prelude(),
            concat!(
                include_str!("conv_winograd_common.wgsl"),
                include_str!("conv_winograd_grad.wgsl")
            )
        );
        let module = shader(ctx, label, &source);
        Self {
            part: Kernel::labelled(ctx, &module, "winograd_weight_part", label),
            sum: Kernel::labelled(
                ctx,
                &module,
                "winograd_weight_sum",
                &format!("{label} (sum)"),
            ),
        }
    }
}

/// The 3×3 layers' forward (stored maps in and out), input gradient (f32 maps in and out) and
/// weight gradient (a stored map and an f32 gradient in).
#[derive(Debug)]
pub struct ConvWinograd {
    forward: Pass,
    grad: Pass,
    weight_grad: WeightGrad,
}

impl ConvWinograd {
    /// Channels a pass should sum at least: one staged slice (conv_winograd.wgsl's BK).
    pub const MIN_SUMMED: u32 = 32;

    /// Whether a layer of `channels` in and out fits: its transformed weights, and the
    /// partials of one range of the weight gradient, each in one binding.
    pub fn fits(ctx: &GpuContext, channels: u32) -> bool {
        let pairs = u64::from(channels).pow(2);
        (POSITIONS * pairs + u64::from(channels)) * 4 <= ctx.binding_limit()
    }

    pub fn new(ctx: &GpuContext, precision: MapPrecision) -> Self {
        Self {
            forward: Pass::new(ctx, precision, "map_t", "map_t"),
            grad: Pass::new(ctx, precision, "f32", "f32"),
            weight_grad: WeightGrad::new(ctx, precision),
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
            images: size.images,
            parts: 0,
            range: 0,
            pad: 0,
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

    /// The weight and bias gradients of a 3×3 `layer` from its input maps and its output's
    /// gradient, summed over every pixel of `size.images` renders, written into `v_params`.
    #[allow(clippy::too_many_arguments)]
    pub fn weight_grad(
        &self,
        rec: &mut Recorder,
        ws: &mut Workspace,
        layer: ConvLayer,
        size: MapSize,
        input: &dyn Bind,
        v_out: &dyn Bind,
        v_params: &dyn Bind,
    ) {
        let mut u = Self::uniform(layer, size, false);
        let tiles = u.tiles_x * u.tiles_y * size.images;
        let pairs = u.outputs * u.summed;
        let part_bytes = (POSITIONS * u64::from(pairs) + u64::from(u.outputs)) * 4;
        // Ranges of whole staged slices, about TARGET_PARTS of them (enough workgroups to fill
        // a GPU, 16 positions each), fewer where their partials would outgrow a binding.
        let fit = u32::try_from(rec.ctx().binding_limit() / part_bytes).unwrap_or(u32::MAX);
        u.range = tiles
            .div_ceil(TARGET_PARTS.min(fit).max(1))
            .next_multiple_of(SLICE)
            .max(SLICE);
        u.parts = tiles.div_ceil(u.range);
        let partials = ws.buffer(
            rec.ctx(),
            "winograd weight partials",
            part_bytes * u64::from(u.parts),
        );
        let uniform = rec.uniform(&u);
        let blocks = u.outputs.div_ceil(BLOCK_M) * u.summed.div_ceil(BLOCK_M);
        self.weight_grad.part.dispatch(
            rec,
            &[(0, &uniform), (1, input), (2, v_out), (3, &partials)],
            [POSITIONS as u32, u.parts, blocks],
        );
        self.weight_grad.sum.dispatch_1d(
            rec,
            &[(0, &uniform), (3, &partials), (4, v_params)],
            pairs.div_ceil(SUM_PAIRS),
        );
    }
}
