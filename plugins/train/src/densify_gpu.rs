//! INRIA `densify_and_prune` recorded on the GPU (densify.wgsl, gather_rows.wgsl): the
//! decisions of `plan_densify`, made per Gaussian in parallel, and every parameter group and
//! Adam moment rearranged in place, without a read-back or a new buffer once the workspace
//! has grown. The caller guarantees room for twice the Gaussians in every group.

use cocog_engine::splat::QUAT_TO_ROT_WGSL;
use cocog_engine::{
    GpuBuffer, GpuContext, Kernel, ParamBuffers, PrefixSum, Recorder, Workspace,
    sh_coeffs_per_channel, shader,
};

use crate::{DensifyConfig, DepthAxis, SplitNoise};

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    n: u32,
    bound: u32,
    seed_lo: u32,
    seed_hi: u32,
    iteration: u32,
    depth_mode: u32,
    pad0: [u32; 2],
    grad_threshold: f32,
    dense: f32,
    min_opacity: f32,
    large: f32,
    depth_range: f32,
    pad1: [f32; 3],
    origin: [f32; 4],
    forward: [f32; 4],
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct GatherParams {
    stride: u32,
    mode: u32,
    bound: u32,
    bury_first: f32,
    bury_rest: f32,
    pad: [u32; 3],
}

/// The opacity logit of a buried row: an opacity of 9e-14, which projection culls (no pixel
/// could reach 1/255), with every derivative still finite.
pub const BURIED_OPACITY_LOGIT: f32 = -30.0;

/// The log-scale of a buried row: a speck, should anything ever draw it.
pub const BURIED_LOG_SCALE: f32 = -10.0;

/// How `gather_rows` fills a group's new rows.
#[derive(Clone, Copy)]
#[repr(u32)]
enum Mode {
    Copy = 0,
    Means = 1,
    LogScales = 2,
    Moments = 3,
}

/// One densification's inputs besides the parameters.
pub struct DensifyInputs<'a> {
    pub config: &'a DensifyConfig,
    /// The length the world-space rules are relative to.
    pub scale: f64,
    pub prune_large: bool,
    pub noise: SplitNoise,
    pub axis: &'a DepthAxis,
    /// Σ‖∂loss/∂mean2d‖ and the visible-view count per Gaussian.
    pub accum: &'a GpuBuffer,
    pub denom: &'a GpuBuffer,
    /// Adam moment buffers (m and v of each group) with their floats per Gaussian.
    pub moments: &'a [(&'a GpuBuffer, u32)],
}

/// After `record` is submitted, `counts` holds [Gaussians after, kept, cloned, split] as u32.
pub struct Recorded {
    pub counts: GpuBuffer,
}

#[derive(Debug)]
pub struct GpuDensify {
    classify: Kernel,
    place: Kernel,
    survive: Kernel,
    gather: Kernel,
    scan: PrefixSum,
}

impl GpuDensify {
    pub fn new(ctx: &GpuContext) -> Self {
        let src = format!("{QUAT_TO_ROT_WGSL}\n{}", include_str!("densify.wgsl"));
        let module = shader(ctx, "densify", &src);
        let gather = shader(ctx, "gather rows", include_str!("gather_rows.wgsl"));
        Self {
            classify: Kernel::new(ctx, &module, "classify"),
            place: Kernel::new(ctx, &module, "place_candidates"),
            survive: Kernel::new(ctx, &module, "mark_survivors"),
            gather: Kernel::new(ctx, &gather, "gather_rows"),
            scan: PrefixSum::new(ctx),
        }
    }

    /// Records densifying the first `params.num_gaussians` Gaussians of `params`, in place.
    /// Every group (and moment buffer) must have room for 2 × that many rows. Rows from the
    /// new count to 2 × the old one are buried: mean 0, log-scales `BURIED_LOG_SCALE`, the
    /// identity rotation, opacity logit `BURIED_OPACITY_LOGIT`, SH and Adam moments 0, so a
    /// caller that does not know the count yet can train all of them.
    pub fn record(
        &self,
        rec: &mut Recorder,
        ws: &mut Workspace,
        params: &ParamBuffers,
        inputs: &DensifyInputs,
    ) -> Recorded {
        let ctx = rec.ctx();
        let n = params.num_gaussians;
        let bound = 2 * n;
        let slots = |ws: &mut Workspace, name| ws.buffer(ctx, name, u64::from(n + 1) * 4);
        let keep = slots(ws, "densify keep slots");
        let clone = slots(ws, "densify clone slots");
        let split = slots(ws, "densify split slots");
        let candidates = ws.buffer(ctx, "densify candidates", u64::from(bound) * 4);
        let shapes = ws.buffer(ctx, "densify child shapes", u64::from(bound) * 24);
        let depth = ws.buffer(ctx, "densify depth range", 8);
        let survive = ws.buffer(ctx, "densify survive slots", u64::from(bound + 1) * 4);
        let counts = ws.buffer(ctx, "densify counts", 16);

        let uniform = rec.uniform(&self.uniform(n, inputs));
        let bindings: [(u32, &dyn cocog_engine::Bind); 14] = [
            (0, &uniform),
            (1, inputs.accum),
            (2, inputs.denom),
            (3, &params.means),
            (4, &params.log_scales),
            (5, &params.quats),
            (6, &params.opacity_logits),
            (7, &keep),
            (8, &clone),
            (9, &split),
            (10, &candidates),
            (11, &shapes),
            (12, &depth),
            (13, &survive),
        ];
        let pick = |ids: &[u32]| -> Vec<(u32, &dyn cocog_engine::Bind)> {
            bindings
                .iter()
                .filter(|(b, _)| ids.contains(b))
                .map(|&(b, r)| (b, r))
                .collect()
        };
        let groups = |threads: u32| threads.div_ceil(256);
        self.classify
            .dispatch_1d(rec, &pick(&[0, 1, 2, 4, 7, 8, 9, 12]), groups(n + 1));
        for s in [&keep, &clone, &split] {
            self.scan.encode(rec, ws, s, n + 1);
        }
        self.place
            .dispatch_1d(rec, &pick(&[0, 3, 4, 5, 7, 8, 9, 10, 11, 12]), groups(n));
        self.survive.dispatch_1d(
            rec,
            &pick(&[0, 3, 4, 6, 7, 8, 9, 10, 11, 12, 13]),
            groups(bound + 1),
        );
        self.scan.encode(rec, ws, &survive, bound + 1);

        let sh_stride = 3 * sh_coeffs_per_channel(params.sh_degree) as u32;
        // (group, floats per row, how new rows fill, buried row's first and other floats)
        let groups_and_modes: Vec<(&GpuBuffer, u32, Mode, [f32; 2])> = [
            (&params.means, 3, Mode::Means, [0.0; 2]),
            (
                &params.log_scales,
                3,
                Mode::LogScales,
                [BURIED_LOG_SCALE; 2],
            ),
            (&params.quats, 4, Mode::Copy, [1.0, 0.0]),
            (
                &params.opacity_logits,
                1,
                Mode::Copy,
                [BURIED_OPACITY_LOGIT; 2],
            ),
            (&params.sh, sh_stride, Mode::Copy, [0.0; 2]),
        ]
        .into_iter()
        .chain(
            inputs
                .moments
                .iter()
                .map(|&(b, s)| (b, s, Mode::Moments, [0.0; 2])),
        )
        .collect();
        let widest = groups_and_modes.iter().map(|g| g.1).max().unwrap_or(1);
        let copy = ws.buffer(
            ctx,
            "densify row copy",
            u64::from(n) * u64::from(widest) * 4,
        );
        for (group, stride, mode, bury) in groups_and_modes {
            let bytes = u64::from(n) * u64::from(stride) * 4;
            if bytes > 0 {
                rec.encoder()
                    .copy_buffer_to_buffer(group, 0, &copy, 0, bytes);
            }
            let gather = rec.uniform(&GatherParams {
                stride,
                mode: mode as u32,
                bound,
                bury_first: bury[0],
                bury_rest: bury[1],
                pad: [0; 3],
            });
            self.gather.dispatch_1d(
                rec,
                &[
                    (0, &gather),
                    (1, &candidates),
                    (2, &shapes),
                    (3, &survive),
                    (4, &copy),
                    (5, group),
                ],
                groups(bound),
            );
        }
        let enc = rec.encoder();
        enc.copy_buffer_to_buffer(&survive, u64::from(bound) * 4, &counts, 0, 4);
        enc.copy_buffer_to_buffer(&keep, u64::from(n) * 4, &counts, 4, 4);
        enc.copy_buffer_to_buffer(&clone, u64::from(n) * 4, &counts, 8, 4);
        enc.copy_buffer_to_buffer(&split, u64::from(n) * 4, &counts, 12, 4);
        Recorded { counts }
    }

    fn uniform(&self, n: u32, inputs: &DensifyInputs) -> Params {
        let c = inputs.config;
        let depth_mode = match inputs.axis.forward {
            _ if c.depth_prune_range <= 1.0 => 0,
            Some(_) => 1,
            None => 2,
        };
        let o = inputs.axis.origin;
        let f = inputs.axis.forward.unwrap_or([0.0; 3]);
        Params {
            n,
            bound: 2 * n,
            seed_lo: inputs.noise.seed as u32,
            seed_hi: (inputs.noise.seed >> 32) as u32,
            iteration: inputs.noise.iteration,
            depth_mode,
            pad0: [0; 2],
            grad_threshold: c.grad_threshold,
            dense: (f64::from(c.percent_dense) * inputs.scale) as f32,
            min_opacity: c.min_opacity,
            large: if inputs.prune_large {
                (f64::from(c.prune_large) * inputs.scale) as f32
            } else {
                f32::INFINITY
            },
            depth_range: c.depth_prune_range,
            pad1: [0.0; 3],
            origin: [o[0] as f32, o[1] as f32, o[2] as f32, 0.0],
            forward: [f[0] as f32, f[1] as f32, f[2] as f32, 0.0],
        }
    }
}
