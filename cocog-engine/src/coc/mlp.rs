//! h_θ's trunk and heads as tiled matrix products over all Gaussians of a step (one row per
//! Gaussian): the forward layers, the transposed products that carry the gradient back
//! through them (masked by each ReLU), and the weight gradients, which sum over every
//! Gaussian with split K.

use super::layout::{CAMERA_DIM, MEAN_DIM, MlpLayout, ROW_DIM};
use crate::core::{GpuBuffer, GpuContext, Recorder, Workspace};
use crate::prims::{Gemm, GemmLayout, GemmShape, GemmTile};

/// Y = X·Wᵀ + b (ReLU'd on trunk layers). X is [Gaussian][row], Y [Gaussian][fan out]. u2/u3
/// are the layer's weight and bias offsets in the flat parameter buffer, u4 the ReLU, u5 the
/// weights' row length (fan in); row feature k is weight column k, or k + u7 from u6 on (the
/// first layer's rows skip the camera's columns); u8: the bias is `camera`'s (with the camera
/// columns' products added).
const FORWARD: &str = "
@group(0) @binding(2) var<storage, read> weights: array<f32>;
@group(0) @binding(3) var<storage, read> x: array<f32>;
@group(0) @binding(4) var<storage, read_write> y: array<f32>;
@group(0) @binding(5) var<storage, read> camera: array<f32>;
fn load_a(b: u32, m: u32, k: u32) -> f32 { return x[m * gemm.k + k]; }
fn load_b(b: u32, k: u32, n: u32) -> f32 {
    return weights[gemm.u2 + n * gemm.u5 + k + select(0u, gemm.u7, k >= gemm.u6)];
}
fn epilogue(b: u32, m: u32, n: u32, v: f32) {
    var o = v;
    if gemm.u8 == 1u {
        o += camera[n];
    } else {
        o += weights[gemm.u3 + n];
    }
    if gemm.u4 == 1u { o = max(o, 0.0); }
    y[m * gemm.n + n] = o;
}
";

/// ∂/∂Y of the layer below = (∂/∂Y · W) masked where that layer's ReLU was off (the input X
/// of this layer is its output). M Gaussians, N = fan in, K = fan out; u2 the weight offset.
const INPUT_GRAD: &str = "
@group(0) @binding(2) var<storage, read> weights: array<f32>;
@group(0) @binding(3) var<storage, read> dy: array<f32>;
@group(0) @binding(4) var<storage, read> x: array<f32>;
@group(0) @binding(5) var<storage, read_write> dx: array<f32>;
fn load_a(b: u32, m: u32, k: u32) -> f32 { return dy[m * gemm.k + k]; }
fn load_b(b: u32, k: u32, n: u32) -> f32 { return weights[gemm.u2 + k * gemm.n + n]; }
fn epilogue(b: u32, m: u32, n: u32, v: f32) {
    let at = m * gemm.n + n;
    dx[at] = select(0.0, v, x[at] > 0.0);
}
";

/// ∂/∂W[o][i] = Σ_g ∂/∂Y[g][o]·X[g][i], and the bias as B's column of ones (i = the row
/// length), which the product sums on the side (`GemmLayout::ones_column`). M = fan out,
/// N = row + 1, K = Gaussians; u0 the row length, u2/u3 the offsets, u5–u7 the columns as in
/// the forward. With u8, the camera's columns are γ(x_cam) (`camera`, from u9) times the
/// bias's gradient: every Gaussian's row held the same γ(x_cam).
const WEIGHT_GRAD: &str = "
@group(0) @binding(2) var<storage, read> dy: array<f32>;
@group(0) @binding(3) var<storage, read> x: array<f32>;
@group(0) @binding(4) var<storage, read_write> v_weights: array<f32>;
@group(0) @binding(5) var<storage, read> camera: array<f32>;
fn load_a(b: u32, m: u32, k: u32) -> f32 { return dy[k * gemm.m + m]; }
fn load_b(b: u32, k: u32, n: u32) -> f32 { return x[k * gemm.u0 + n]; }
fn epilogue(b: u32, m: u32, n: u32, v: f32) {
    let row = gemm.u2 + m * gemm.u5;
    if n == gemm.u0 {
        v_weights[gemm.u3 + m] = v;
        if gemm.u8 == 1u {
            for (var j = 0u; j < gemm.u7; j++) {
                v_weights[row + gemm.u6 + j] = camera[gemm.u9 + j] * v;
            }
        }
    } else {
        v_weights[row + n + select(0u, gemm.u7, n >= gemm.u6)] = v;
    }
}
";

/// The compiled products of one MLP shape.
#[derive(Debug)]
pub(super) struct MlpKernels {
    layout: MlpLayout,
    forward: Gemm,
    input_grad: Gemm,
    weight_grad: Gemm,
}

/// Activations of one step, each [Gaussian][width]: the input rows (`ROW_DIM` wide), the
/// three hidden layers' outputs (after ReLU) and the heads; and the step's camera terms, which
/// every row shares.
#[derive(Debug)]
pub struct MlpActivations {
    pub input: GpuBuffer,
    /// The first layer's bias with its camera columns times γ(x_cam) added (`width` values),
    /// then γ(x_cam) (`CAMERA_DIM`).
    pub camera: GpuBuffer,
    pub hidden: [GpuBuffer; 3],
    pub heads: GpuBuffer,
}

impl MlpActivations {
    /// Layer l's input (0: the embedded rows; 1–3: the hidden outputs).
    fn layer_input(&self, l: usize) -> &GpuBuffer {
        if l == 0 {
            &self.input
        } else {
            &self.hidden[l - 1]
        }
    }
}

impl MlpKernels {
    pub fn new(ctx: &GpuContext, layout: MlpLayout) -> Self {
        // Only the weight gradient sums over Gaussians, and only it has the bias's ones column.
        let gemm = |label: &str, src: &str, a_k_fast: bool, b_k_fast: bool, split_k: bool| {
            Gemm::new(
                ctx,
                label,
                src,
                GemmLayout {
                    a_k_fast,
                    b_k_fast,
                    split_k,
                    ones_column: split_k,
                    tile: GemmTile::SQUARE,
                },
            )
        };
        Self {
            layout,
            forward: gemm("coc mlp forward", FORWARD, true, true, false),
            input_grad: gemm("coc mlp input grad", INPUT_GRAD, true, false, false),
            weight_grad: gemm("coc mlp weight grad", WEIGHT_GRAD, false, false, true),
        }
    }

    /// Buffers for `n` Gaussians' activations, from the workspace.
    pub fn activations(&self, ctx: &GpuContext, ws: &mut Workspace, n: u32) -> MlpActivations {
        let rows = u64::from(n) * 4;
        let l = &self.layout;
        let w = l.width as u64;
        MlpActivations {
            input: ws.buffer(ctx, "coc mlp input", rows * ROW_DIM as u64),
            camera: ws.buffer(ctx, "coc camera terms", (w + CAMERA_DIM as u64) * 4),
            hidden: [
                ws.buffer(ctx, "coc mlp hidden 1", rows * w),
                ws.buffer(ctx, "coc mlp hidden 2", rows * w),
                ws.buffer(ctx, "coc mlp hidden 3", rows * w),
            ],
            heads: ws.buffer(ctx, "coc mlp heads", rows * l.outputs as u64),
        }
    }

    /// Records the trunk and heads over `n` Gaussians whose input rows are in `acts.input`.
    pub fn encode_forward(
        &self,
        rec: &mut Recorder,
        ws: &mut Workspace,
        weights: &wgpu::Buffer,
        acts: &MlpActivations,
        n: u32,
    ) {
        for (l, &(fan_in, fan_out, w, b)) in self.layout.layers.iter().enumerate() {
            let out = if l < 3 { &acts.hidden[l] } else { &acts.heads };
            let c = Columns::of_layer(l, fan_in);
            let shape = GemmShape {
                m: n,
                n: fan_out as u32,
                k: c.row,
                params: params(&[
                    0,
                    0,
                    w as u32,
                    b as u32,
                    u32::from(l < 3),
                    fan_in as u32,
                    c.gap_at,
                    c.gap,
                    c.folded,
                ]),
                ..Default::default()
            };
            let x = acts.layer_input(l);
            self.forward.encode(
                rec,
                ws,
                shape,
                &[(2, weights), (3, x), (4, out), (5, &acts.camera)],
            );
        }
    }

    /// Records the weight gradients (every entry of `v_weights` is written) from the heads'
    /// gradient `d_heads` ([Gaussian][heads]).
    pub fn encode_backward(
        &self,
        rec: &mut Recorder,
        ws: &mut Workspace,
        weights: &wgpu::Buffer,
        acts: &MlpActivations,
        d_heads: &GpuBuffer,
        v_weights: &wgpu::Buffer,
        n: u32,
    ) {
        let ctx = rec.ctx();
        let bytes = u64::from(n) * self.layout.width as u64 * 4;
        let ping = [
            ws.buffer(ctx, "coc mlp delta a", bytes),
            ws.buffer(ctx, "coc mlp delta b", bytes),
        ];
        let mut dy = d_heads.clone();
        for l in (0..4).rev() {
            let (fan_in, fan_out, w, b) = self.layout.layers[l];
            let x = acts.layer_input(l);
            let c = Columns::of_layer(l, fan_in);
            let shape = GemmShape {
                m: fan_out as u32,
                n: c.row + 1,
                k: n,
                params: params(&[
                    c.row,
                    0,
                    w as u32,
                    b as u32,
                    0,
                    fan_in as u32,
                    c.gap_at,
                    c.gap,
                    c.folded,
                    self.layout.width as u32,
                ]),
                ..Default::default()
            };
            self.weight_grad.encode(
                rec,
                ws,
                shape,
                &[(2, &dy), (3, x), (4, v_weights), (5, &acts.camera)],
            );
            if l == 0 {
                break;
            }
            let dx = ping[l % 2].clone();
            let shape = GemmShape {
                m: n,
                n: fan_in as u32,
                k: fan_out as u32,
                params: params(&[0, 0, w as u32]),
                ..Default::default()
            };
            self.input_grad
                .encode(rec, ws, shape, &[(2, weights), (3, &dy), (4, x), (5, &dx)]);
            dy = dx;
        }
    }
}

/// How a layer's input rows map onto its weights' columns: the first layer's rows skip the
/// camera's columns (`gap` of them from `gap_at`), whose products come folded into the bias.
struct Columns {
    row: u32,
    gap_at: u32,
    gap: u32,
    folded: u32,
}

impl Columns {
    fn of_layer(l: usize, fan_in: usize) -> Self {
        if l == 0 {
            Self {
                row: ROW_DIM as u32,
                gap_at: MEAN_DIM as u32,
                gap: CAMERA_DIM as u32,
                folded: 1,
            }
        } else {
            Self {
                row: fan_in as u32,
                gap_at: fan_in as u32,
                gap: 0,
                folded: 0,
            }
        }
    }
}

fn params(v: &[u32]) -> [u32; 10] {
    let mut out = [0; 10];
    out[..v.len()].copy_from_slice(v);
    out
}
