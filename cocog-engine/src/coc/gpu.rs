//! Recording h_θ, the expansion and their adjoint into a training step: per-Gaussian kernels
//! at both ends (forward.wgsl, backward.wgsl), the trunk as matrix products (mlp.rs). Every
//! per-step buffer comes from the caller's `Workspace`.

use super::layout::{
    CAMERA_DIM, CAMERA_FREQS, CocConfig, CocVariant, INPUT_DIM, MEAN_DIM, MEAN_FREQS, ROW_DIM,
};
use super::mlp::{MlpActivations, MlpKernels};
use crate::ParamBuffers;
use crate::core::{GpuBuffer, GpuContext, Kernel, Recorder, Workspace, shader};

/// What changes per step: the view and its camera centre.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CocStep {
    /// Index of the training view, into the focus buffer.
    pub view: u32,
    pub camera_centre: [f32; 3],
    /// The scene scale D: h_θ sees lengths divided by it and positions measured from
    /// `origin`; the focus buffer holds d_F / D (the released code learns d_F / max depth).
    pub focus_scale: f32,
    pub origin: [f32; 3],
    /// Multiplies every circle of confusion: 1 as photographed (training), 0 a pinhole;
    /// refocused renders choose it.
    pub aperture: f32,
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct StepUniform {
    n: u32,
    view: u32,
    focus_scale: f32,
    aperture: f32,
    centre: [f32; 3],
    pad0: u32,
    origin: [f32; 3],
    pad1: u32,
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Sizes {
    len: u32,
    sets: u32,
    pad: [u32; 2],
}

/// The M + 1 sets of a step, `[set][base]`, plus what the backward replays.
#[derive(Debug)]
pub struct CocExpansion {
    pub means: GpuBuffer,
    pub log_scales: GpuBuffer,
    pub quats: GpuBuffer,
    /// h_θ's input, hidden activations and heads, one row per Gaussian.
    pub acts: MlpActivations,
    /// Per Gaussian: the gate |1/d − 1/d_F|, its derivative in the focus parameter, the
    /// normalised depth and the aperture K (paper and lens variants).
    pub gates: GpuBuffer,
    pub num_gaussians: u32,
}

/// Gradients of the base Gaussians' means, log-scales and rotations (summed over the sets),
/// of h_θ's weights, and of the focus buffer (non-zero at the step's view only).
#[derive(Debug)]
pub struct CocGrads {
    pub v_means: GpuBuffer,
    pub v_log_scales: GpuBuffer,
    pub v_quats: GpuBuffer,
    pub v_weights: GpuBuffer,
    pub v_focus: GpuBuffer,
    /// The lens variant's per-view aperture (zero for the others).
    pub v_aperture: GpuBuffer,
}

/// The compiled CoC kernels for one `CocConfig`.
#[derive(Debug)]
pub struct CocKernels {
    config: CocConfig,
    embed: Kernel,
    fold_camera: Kernel,
    expand: Kernel,
    mlp: MlpKernels,
    backward: Kernel,
    focus_sum: Kernel,
    sum_sets: Kernel,
}

/// WGSL constants of this configuration, prepended to every CoC shader.
fn prelude(config: &CocConfig) -> String {
    let hl = config.heads();
    let width = config.width;
    let (_, _, w0, b0) = config.mlp().layers[0];
    let s = format!(
        "const M: u32 = {m}u;\nconst WIDTH: u32 = {width}u;\nconst HEADS: u32 = {heads}u;\n\
         const PAPER: bool = {paper};\nconst LENS: bool = {lens};\nconst CENTRED: bool = {centred};\nconst MODULATE_BASE: bool = {modulate_base};\nconst H_APERTURE: u32 = {ha}u;\nconst H_BETA: u32 = {hb}u;\n\
         const H_POS: u32 = {hp}u;\nconst H_SCALE: u32 = {hs}u;\nconst H_ROT: u32 = {hr}u;\n\
         const IN_DIM: u32 = {INPUT_DIM}u;\nconst MEAN_FREQS: u32 = {MEAN_FREQS}u;\n\
         const CAMERA_FREQS: u32 = {CAMERA_FREQS}u;\nconst MEAN_DIM: u32 = {MEAN_DIM}u;\n\
         const CAMERA_DIM: u32 = {CAMERA_DIM}u;\nconst ROW_DIM: u32 = {ROW_DIM}u;\n\
         const W0: u32 = {w0}u;\nconst W0_BIAS: u32 = {b0}u;\n",
        m = hl.copies,
        heads = hl.len,
        paper = config.variant == CocVariant::Paper,
        lens = config.variant == CocVariant::Lens,
        centred = config.centred,
        modulate_base = config.modulate_base,
        ha = hl.aperture.unwrap_or(0),
        hb = hl.beta.unwrap_or(0),
        hp = hl.pos,
        hs = hl.scale,
        hr = hl.rot,
    );
    s + include_str!("common.wgsl")
}

impl CocKernels {
    pub fn new(ctx: &GpuContext, config: CocConfig) -> Self {
        let pre = prelude(&config);
        let module = |name: &str, body: &str| shader(ctx, name, &format!("{pre}\n{body}"));
        let fwd = module("coc forward", include_str!("forward.wgsl"));
        let bwd = module("coc backward", include_str!("backward.wgsl"));
        let red = module("coc reduce", include_str!("reduce.wgsl"));
        let sets = shader(ctx, "coc sum sets", include_str!("sum_sets.wgsl"));
        Self {
            config,
            embed: Kernel::new(ctx, &fwd, "embed"),
            fold_camera: Kernel::new(ctx, &fwd, "fold_camera"),
            expand: Kernel::new(ctx, &fwd, "expand"),
            mlp: MlpKernels::new(ctx, config.mlp()),
            backward: Kernel::new(ctx, &bwd, "backward"),
            focus_sum: Kernel::new(ctx, &red, "focus_sum"),
            sum_sets: Kernel::new(ctx, &sets, "sum_sets"),
        }
    }

    pub fn config(&self) -> &CocConfig {
        &self.config
    }

    fn uniform(&self, rec: &mut Recorder, n: u32, step: &CocStep) -> crate::core::UniformSlot {
        rec.uniform(&StepUniform {
            n,
            view: step.view,
            focus_scale: step.focus_scale,
            aperture: step.aperture,
            centre: step.camera_centre,
            pad0: 0,
            origin: step.origin,
            pad1: 0,
        })
    }

    /// Records h_θ and the expansion of `n` base Gaussians for one view. `focus` holds one
    /// value per training view, and so does `apertures` for the lens variant (any buffer
    /// serves the others).
    pub fn encode_forward(
        &self,
        rec: &mut Recorder,
        ws: &mut Workspace,
        weights: &wgpu::Buffer,
        means: &wgpu::Buffer,
        log_scales: &wgpu::Buffer,
        quats: &wgpu::Buffer,
        focus: &wgpu::Buffer,
        apertures: &wgpu::Buffer,
        n: u32,
        step: &CocStep,
    ) -> CocExpansion {
        let ctx = rec.ctx();
        let sets = u64::from(self.config.copies + 1) * u64::from(n);
        let out = CocExpansion {
            means: ws.buffer(ctx, "coc set means", sets * 12),
            log_scales: ws.buffer(ctx, "coc set log-scales", sets * 12),
            quats: ws.buffer(ctx, "coc set quats", sets * 16),
            acts: self.mlp.activations(ctx, ws, n),
            gates: ws.buffer(ctx, "coc gates", u64::from(n) * 16),
            num_gaussians: n,
        };
        if n == 0 {
            return out;
        }
        let u = self.uniform(rec, n, step);
        let a = &out.acts;
        self.embed.dispatch_1d(
            rec,
            &[
                (0, &u),
                (1, means),
                (2, log_scales),
                (3, quats),
                (5, &a.input),
            ],
            n.div_ceil(64),
        );
        self.fold_camera
            .dispatch(rec, &[(0, &u), (12, weights), (13, &a.camera)], [1, 1, 1]);
        self.mlp.encode_forward(rec, ws, weights, a, n);
        self.expand.dispatch_1d(
            rec,
            &[
                (0, &u),
                (1, means),
                (2, log_scales),
                (3, quats),
                (4, focus),
                (6, &a.heads),
                (7, &out.means),
                (8, &out.log_scales),
                (9, &out.quats),
                (10, &out.gates),
                (11, apertures),
            ],
            n.div_ceil(64),
        );
        out
    }

    /// Records the adjoint: `v_set_*` are the rasterizer's gradients of the expanded sets.
    pub fn encode_backward(
        &self,
        rec: &mut Recorder,
        ws: &mut Workspace,
        weights: &wgpu::Buffer,
        quats: &wgpu::Buffer,
        exp: &CocExpansion,
        v_set_means: &wgpu::Buffer,
        v_set_log_scales: &wgpu::Buffer,
        v_set_quats: &wgpu::Buffer,
        num_views: u32,
        step: &CocStep,
    ) -> CocGrads {
        let ctx = rec.ctx();
        let n = exp.num_gaussians;
        let hl = self.config.heads();
        let params = self.config.mlp().len as u32;
        let grads = CocGrads {
            v_means: ws.buffer(ctx, "coc v means", u64::from(n) * 12),
            v_log_scales: ws.buffer(ctx, "coc v log-scales", u64::from(n) * 12),
            v_quats: ws.buffer(ctx, "coc v quats", u64::from(n) * 16),
            v_weights: ws.zeroed(rec, "coc v weights", u64::from(params) * 4),
            v_focus: ws.zeroed(rec, "coc v focus", u64::from(num_views) * 4),
            v_aperture: ws.zeroed(rec, "coc v aperture", u64::from(num_views) * 4),
        };
        if n == 0 {
            return grads;
        }
        let d_heads = ws.buffer(ctx, "coc d heads", u64::from(n) * hl.len as u64 * 4);
        let terms = ws.buffer(ctx, "coc focus terms", u64::from(n) * 8);
        let u = self.uniform(rec, n, step);
        self.backward.dispatch_1d(
            rec,
            &[
                (0, &u),
                (1, quats),
                (2, &exp.acts.heads),
                (3, &exp.gates),
                (4, v_set_means),
                (5, v_set_log_scales),
                (6, v_set_quats),
                (7, &grads.v_means),
                (8, &grads.v_log_scales),
                (9, &grads.v_quats),
                (10, &d_heads),
                (11, &terms),
            ],
            n.div_ceil(64),
        );
        self.mlp
            .encode_backward(rec, ws, weights, &exp.acts, &d_heads, &grads.v_weights, n);
        self.focus_sum.dispatch(
            rec,
            &[
                (0, &u),
                (1, &terms),
                (2, &grads.v_focus),
                (3, &grads.v_aperture),
            ],
            [1, 1, 1],
        );
        grads
    }

    /// The M + 1 sets as renderable parameters: the expansion's means, scales and rotations,
    /// and the bases' own opacity and SH buffers, which every set reads through its base's
    /// row (`ParamBuffers::shared_rows`) instead of holding a copy. Records nothing.
    pub fn sets(&self, base: &ParamBuffers, exp: &CocExpansion) -> ParamBuffers {
        let sets = self.config.copies + 1;
        ParamBuffers {
            means: exp.means.clone(),
            log_scales: exp.log_scales.clone(),
            quats: exp.quats.clone(),
            opacity_logits: base.opacity_logits.clone(),
            sh: base.sh.clone(),
            sh_degree: base.sh_degree,
            num_gaussians: sets * base.num_gaussians,
            shared_rows: base.num_gaussians,
        }
    }

    /// `dst[j] = Σ_set src[set·len + j]` over the M + 1 sets (opacity and SH gradients, which
    /// the sets share with their base).
    pub fn encode_sum_sets(
        &self,
        rec: &mut Recorder,
        src: &wgpu::Buffer,
        dst: &wgpu::Buffer,
        len: u32,
    ) {
        let sizes = rec.uniform(&Sizes {
            len,
            sets: self.config.copies + 1,
            pad: [0; 2],
        });
        self.sum_sets
            .dispatch_1d(rec, &[(0, &sizes), (1, src), (2, dst)], len.div_ceil(256));
    }
}
