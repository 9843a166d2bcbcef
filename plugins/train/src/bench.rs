//! `cocog bench`: where a training iteration's time goes on this machine's adapter.
//!
//! Trains a scene for a while and reports real throughput (unprofiled iterations) and the
//! split into forward / backward / optimizer / density control (profiled iterations, which
//! wait for the GPU at each phase boundary), with the Gaussian count and peak memory.

use std::path::{Path, PathBuf};
use std::time::Instant;

use cocog_engine::GpuContext;
use cocog_engine::nn::CompositorConfig;
use cocog_pipeline::{Context, Scene, Split, StageError};
use serde::Serialize;

use crate::stage::load;
use crate::{
    CocTrainConfig, DensifyConfig, PhaseTimes, TrainConfig, TrainState, TrainView, Trainer,
};

/// What to measure.
#[derive(Clone, Debug)]
pub struct BenchOptions {
    pub downscale: u32,
    /// Unprofiled iterations, then as many profiled ones.
    pub iterations: u32,
    /// Iterations run first and not counted (pipeline compilation, first allocations).
    pub warmup: u32,
    /// Start from a checkpoint (realistic Gaussian counts) instead of the scene's points.
    pub resume: Option<PathBuf>,
    pub max_sh_degree: u32,
    /// Time CoCoGaussian steps: the sets and F run from the first iteration on.
    pub coc: Option<CocTrainConfig>,
    /// Also time every kernel with GPU timestamps during the profiled iterations (adapters
    /// with timestamp queries).
    pub kernels: bool,
}

/// GPU time of one kernel per iteration.
#[derive(Clone, Debug, Serialize)]
pub struct KernelMs {
    pub kernel: String,
    pub passes_per_iteration: f64,
    pub ms_per_iteration: f64,
}

/// Milliseconds per iteration of each phase.
#[derive(Clone, Debug, Default, Serialize)]
pub struct PhaseMs {
    pub forward: f64,
    pub backward: f64,
    pub optimizer: f64,
    pub density: f64,
    /// CoCoGaussian only: h_θ and the expansion, forward and adjoint.
    pub coc_net: f64,
    /// CoCoGaussian only: the compositor F, forward and backward.
    pub compositor: f64,
    pub total: f64,
}

#[derive(Clone, Debug, Serialize)]
pub struct BenchReport {
    pub adapter: String,
    /// The scene directory, or the synthetic workload's description.
    pub source: String,
    /// `3dgs` or `cocog`.
    pub method: String,
    /// Which gradient-accumulation path the backward used.
    pub float_atomics: bool,
    pub subgroups: bool,
    /// WGSL f16, in which F stores its forward maps.
    pub shader_f16: bool,
    /// The adapter's cooperative matrix (tensor-core) shapes, "none" without.
    pub cooperative_matrices: String,
    /// Cooperative matrices enabled (`COCOG_COOPERATIVE_MATRIX=1` where offered).
    pub cooperative_f16: bool,
    /// How F's convolutions ran (`Compositor::describe`: the kernels built, whatever the
    /// switches asked); None for plain 3DGS.
    pub compositor_path: Option<String>,
    /// F's 3×3 layer ran by Winograd, so its GFLOP are counted as direct convolutions'.
    pub compositor_winograd: bool,
    /// How the compositing forward and backward ran (`COCOG_RASTER_BLOCK`, the tile-list split).
    pub compositing: String,
    /// Whether the kernels were compiled with naga's run-time guards (`COCOG_SHADER_CHECKS`).
    pub shader_checks: bool,
    /// The block layout F's products take on them: `COCOG_COOP_BLOCK`'s where it fits the
    /// adapter, else the default one.
    pub coop_block: Option<String>,
    pub width: u32,
    pub height: u32,
    pub views: usize,
    /// Bands of rows a step trained its frame in (1: the frame fits one buffer binding).
    pub bands: u32,
    pub start_iteration: u32,
    pub gaussians_start: u32,
    pub gaussians_end: u32,
    pub iterations: u32,
    pub it_per_s: f64,
    pub ms_per_iteration: f64,
    /// Of the unprofiled iterations, the wall time the host spent in each step less its
    /// throttle waits for the GPU and its `queue.submit` calls: recording the step. Near
    /// `ms_per_iteration`, the host, not the GPU, bounds the throughput.
    pub host_ms_per_iteration: f64,
    /// Wall time in `queue.submit` per iteration: wgpu's tracking and the driver's submit
    /// (lavapipe's blocks while the device is busy, so there it is mostly waiting).
    pub submit_ms_per_iteration: f64,
    /// Profiled: each phase waited for, so `total` exceeds `ms_per_iteration`.
    pub phases_ms: PhaseMs,
    pub peak_gpu_bytes: u64,
    /// Peak resident memory of the whole process (Linux VmHWM), when known.
    pub peak_host_bytes: Option<u64>,
    /// Engine operations per timed iteration (densification iterations included).
    pub per_iteration: OpsPerIteration,
    /// With `kernels`: GPU time per kernel over the profiled iterations, largest first.
    pub kernels: Vec<KernelMs>,
    /// CoCoGaussian only: floating-point operations of F's convolutions per iteration,
    /// forward and backward (`CompositorConfig::flops`; with F in chunks, also the backward's
    /// recompute of each chunk's layers), and what the compositor phase's
    /// time makes of them.
    pub compositor_gflop: Option<f64>,
    pub compositor_gflop_per_s: Option<f64>,
}

/// Mean engine operations per iteration: what issue #11's execution model drives to
/// (0, 0, 1) for buffers, blocking reads and submissions.
#[derive(Clone, Debug, Serialize)]
pub struct OpsPerIteration {
    pub buffers_created: f64,
    pub blocking_reads: f64,
    pub throttle_waits: f64,
    pub submissions: f64,
    pub dispatches: f64,
    pub bind_groups_created: f64,
}

impl OpsPerIteration {
    fn from(c: cocog_engine::CounterSnapshot, n: u32) -> Self {
        let per = |v: u64| v as f64 / f64::from(n.max(1));
        Self {
            buffers_created: per(c.buffers_created),
            blocking_reads: per(c.blocking_reads),
            throttle_waits: per(c.throttle_waits),
            submissions: per(c.submissions),
            dispatches: per(c.dispatches),
            bind_groups_created: per(c.bind_groups_created),
        }
    }
}

fn per_iteration(t: &PhaseTimes, n: u32) -> PhaseMs {
    let ms = |s: f64| 1e3 * s / f64::from(n.max(1));
    PhaseMs {
        forward: ms(t.forward),
        backward: ms(t.backward),
        optimizer: ms(t.optimizer),
        density: ms(t.density),
        coc_net: ms(t.coc_net),
        compositor: ms(t.compositor),
        total: ms(t.total()),
    }
}

/// Peak resident set size from /proc (None elsewhere).
fn peak_host_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

/// Runs the benchmark on the scene directory `scene_dir`.
pub fn run_bench(
    scene_dir: &Path,
    opts: &BenchOptions,
    ctx: &dyn Context,
) -> Result<BenchReport, StageError> {
    let mut scene = Scene::load(scene_dir)?;
    scene.rebase(scene_dir)?;
    let resume = match &opts.resume {
        Some(p) => Some(TrainState::load(p).map_err(|e| StageError::Input(e.to_string()))?),
        None => None,
    };
    let start = resume.as_ref().map_or(0, |s| s.iteration);
    let config = TrainConfig {
        // The default schedule, with density control from the first iteration at its usual
        // interval, so a short run from the SfM points measures it too.
        densify: Some(DensifyConfig {
            from_iter: start.min(500),
            ..DensifyConfig::auto()
        }),
        ..bench_config(start, opts)
    };
    let scratch = tempfile_dir(scene_dir)?;
    let views = load::split_views(
        &scene,
        scene_dir,
        Split::Train,
        opts.downscale,
        config.background,
        scratch.path(),
        ctx,
    )?;
    drop(scratch);
    let gpu = GpuContext::new().map_err(StageError::other)?;
    let trainer = match &resume {
        Some(state) => Trainer::resume(&gpu, state, &views, config),
        None => {
            let init = load::initial_gaussians(&scene, scene_dir)?;
            Trainer::new(&gpu, &init, &views, config)
        }
    }
    .map_err(StageError::other)?;
    let source = scene_dir.display().to_string();
    measure(&gpu, trainer, &views, start, source, opts, ctx)
}

/// A dataset-free workload: `gaussians` random Gaussians in a ball seen by a ring of `views`
/// cameras (`cocog_synth::workload`), for step times at any count and resolution.
#[derive(Clone, Debug)]
pub struct SyntheticSpec {
    pub gaussians: u32,
    pub width: u32,
    pub height: u32,
    pub views: u32,
    pub seed: u64,
    /// Focal length × this (≥ 1): part of the Gaussians then fall outside each frame.
    pub zoom: f64,
    /// Also write the workload here (`gaussians.ply`, INRIA layout, and `cameras.json`), so a
    /// peer rasterizer can time the same Gaussians (`bench/peer_gsplat.py --workload`).
    pub write_to: Option<PathBuf>,
}

/// Runs the benchmark on a synthetic workload: the count stays fixed (no density control) and
/// every Gaussian carries SH of `opts.max_sh_degree`, all of it active from the third
/// iteration, so the timed steps do the full work at the count asked for.
pub fn run_bench_synthetic(
    spec: &SyntheticSpec,
    opts: &BenchOptions,
    ctx: &dyn Context,
) -> Result<BenchReport, StageError> {
    if spec.gaussians == 0 || spec.views == 0 || spec.width == 0 || spec.height == 0 {
        return Err(StageError::Options(format!(
            "a synthetic workload needs Gaussians, views and a size, got {spec:?}"
        )));
    }
    if !(spec.zoom.is_finite() && spec.zoom >= 1.0) {
        return Err(StageError::Options(format!(
            "--zoom must be a number >= 1 (1 keeps the whole ball in every frame), got {}",
            spec.zoom
        )));
    }
    ctx.info(&format!(
        "synthetic workload: {} Gaussians, {} views of {}×{}, seed {}",
        spec.gaussians, spec.views, spec.width, spec.height, spec.seed
    ));
    let mut work = cocog_synth::workload::random_workload(
        spec.gaussians as usize,
        spec.width,
        spec.height,
        spec.views as usize,
        opts.max_sh_degree,
        spec.seed,
    );
    work.zoom(spec.zoom);
    if let Some(dir) = &spec.write_to {
        write_workload(dir, &work)?;
        ctx.info(&format!("workload written to {}", dir.display()));
    }
    // The photos' content does not change the work of a step; smooth, distinct per view.
    let views: Vec<TrainView> = (work.cameras.iter().enumerate())
        .map(|(k, camera)| {
            let (w, h) = (camera.width as f32, camera.height as f32);
            let image = (0..camera.height)
                .flat_map(|y| (0..camera.width).map(move |x| (x as f32, y as f32)))
                .map(|(x, y)| [x / w, y / h, 0.5 + 0.4 * (k as f32).sin()])
                .collect();
            TrainView {
                camera: *camera,
                image,
            }
        })
        .collect();
    let config = TrainConfig {
        sh_degree_interval: 1,
        densify: None,
        ..bench_config(0, opts)
    };
    let gpu = GpuContext::new().map_err(StageError::other)?;
    let trainer = Trainer::new(&gpu, &work.gaussians, &views, config).map_err(StageError::other)?;
    let mut source = format!(
        "synthetic: {} random Gaussians, seed {}",
        spec.gaussians, spec.seed
    );
    if spec.zoom != 1.0 {
        source += &format!(
            ", zoom {}: {:.1}% of the means in each frame",
            spec.zoom,
            100.0 * work.in_frame()
        );
    }
    measure(&gpu, trainer, &views, 0, source, opts, ctx)
}

/// `gaussians.ply` and `cameras.json` (per camera: fx, fy, cx, cy, width, height and the
/// OpenCV `world_from_camera`), each written whole or not at all.
fn write_workload(dir: &Path, work: &cocog_synth::workload::Workload) -> Result<(), StageError> {
    std::fs::create_dir_all(dir).map_err(|e| StageError::io(dir, e))?;
    let ply = dir.join("gaussians.ply");
    cocog_formats::ply::write_splats(&ply, &(&work.gaussians).into(), None)
        .map_err(StageError::other)?;
    let cameras: Vec<serde_json::Value> = (work.cameras.iter())
        .map(|c| {
            serde_json::json!({
                "fx": c.fx, "fy": c.fy, "cx": c.cx, "cy": c.cy,
                "width": c.width, "height": c.height,
                "world_from_camera": c.world_from_camera,
            })
        })
        .collect();
    let json = serde_json::to_vec_pretty(&serde_json::json!({ "cameras": cameras }))
        .map_err(StageError::other)?;
    let path = dir.join("cameras.json");
    cocog_formats::write_atomic(&path, |w| {
        std::io::Write::write_all(w, &json).map_err(|e| cocog_formats::FormatError::io(&path, e))
    })
    .map_err(StageError::other)
}

/// The run both sources share: `start` + warm-up + timed + profiled iterations, CoCoGaussian
/// (when asked) from the first of them.
fn bench_config(start: u32, opts: &BenchOptions) -> TrainConfig {
    TrainConfig {
        iterations: start + opts.warmup + 2 * opts.iterations,
        max_sh_degree: opts.max_sh_degree,
        loss_every: 0,
        coc: opts.coc.clone().map(|c| CocTrainConfig {
            blur_start: start + 1,
            composite_start: start + 1,
            ..c
        }),
        ..TrainConfig::default()
    }
}

/// Warm-up, then the unprofiled iterations (throughput, engine counters, peak memory), then
/// the profiled ones (phase split, kernel times).
fn measure(
    gpu: &GpuContext,
    mut trainer: Trainer<'_>,
    views: &[TrainView],
    start: u32,
    source: String,
    opts: &BenchOptions,
    ctx: &dyn Context,
) -> Result<BenchReport, StageError> {
    let total = opts.warmup + 2 * opts.iterations;
    let gaussians_start = trainer.num_gaussians();
    // Wall time inside `step`; less its throttle waits, what the host spends on a step.
    let host = std::cell::Cell::new(std::time::Duration::ZERO);
    let mut step = |done: u32| -> Result<_, StageError> {
        ctx.check_cancelled()?;
        ctx.progress("bench", u64::from(done), u64::from(total));
        let t = Instant::now();
        let stats = trainer.step().map_err(StageError::other);
        host.set(host.get() + t.elapsed());
        stats
    };
    for i in 0..opts.warmup {
        step(i)?;
    }
    gpu.wait().map_err(StageError::other)?;
    let warm_host = host.get();
    gpu.memory.reset_peak();
    let ops_before = gpu.counters.snapshot();
    let clock = Instant::now();
    for i in 0..opts.iterations {
        step(opts.warmup + i)?;
    }
    gpu.wait().map_err(StageError::other)?;
    let seconds = clock.elapsed().as_secs_f64();
    let ops = gpu.counters.snapshot() - ops_before;
    let in_steps = (host.get() - warm_host).as_secs_f64();
    let submit_seconds = ops.submit_ns as f64 * 1e-9;
    let host_seconds = in_steps - ops.throttle_wait_ns as f64 * 1e-9 - submit_seconds;
    trainer.set_profiling(true);
    let timing = opts.kernels && gpu.profiler.enable(gpu);
    if opts.kernels && !timing {
        ctx.warn("bench: this adapter has no timestamp queries; no per-kernel times");
    }
    let mut phases = PhaseTimes::default();
    let mut bands = 1;
    for i in 0..opts.iterations {
        let stats = trainer.step().map_err(StageError::other)?;
        bands = bands.max(stats.bands);
        if timing {
            gpu.profiler.collect(gpu).map_err(StageError::other)?;
        }
        ctx.progress(
            "bench",
            u64::from(opts.warmup + opts.iterations + i + 1),
            u64::from(total),
        );
        phases.add(&stats.phases.unwrap_or_default());
    }
    gpu.profiler.disable();
    // Brings in a densification's count still on its way, for `gaussians_end`.
    trainer.finish().map_err(StageError::other)?;
    let n = opts.iterations.max(1);
    let kernels = gpu
        .profiler
        .take()
        .into_iter()
        .map(|k| KernelMs {
            kernel: k.kernel,
            passes_per_iteration: k.passes as f64 / f64::from(n),
            ms_per_iteration: k.ms / f64::from(n),
        })
        .collect();
    let phases_ms = per_iteration(&phases, n);
    let (width, height) = (views[0].camera.width, views[0].camera.height);
    let compositor_gflop = opts.coc.as_ref().map(|c| {
        let f = CompositorConfig::with_channels(c.compositor_channels);
        let (pixels, renders) = (u64::from(width) * u64::from(height), c.net.copies + 1);
        let (fwd, bwd) = f.flops(pixels, renders);
        let chunked = f.renders_per_chunk(gpu.binding_limit(), pixels, renders) < renders;
        let recompute = if chunked {
            f.recompute_flops(pixels, renders)
        } else {
            0.0
        };
        (fwd + bwd + recompute) / 1e9
    });
    Ok(BenchReport {
        adapter: gpu.adapter_name(),
        source,
        method: if opts.coc.is_some() { "cocog" } else { "3dgs" }.to_owned(),
        float_atomics: gpu.float_atomics,
        subgroups: gpu.subgroups,
        shader_f16: gpu.shader_f16,
        cooperative_matrices: gpu.cooperative_matrix_shapes(),
        cooperative_f16: gpu.cooperative.is_some(),
        compositing: compositing_setting(
            trainer.renderer(),
            (width.div_ceil(16), height.div_ceil(16)),
            opts.coc.as_ref().map_or(1, |c| c.net.copies + 1),
        ),
        compositor_path: trainer.compositor().map(|f| f.describe()),
        compositor_winograd: trainer.compositor().is_some_and(|f| f.runs_winograd()),
        shader_checks: cocog_engine::runtime_checks(),
        coop_block: cocog_engine::Gemm::cooperative_block(gpu)
            .map(|b| b.name().unwrap_or("unnamed").to_owned()),
        width,
        height,
        views: views.len(),
        bands,
        start_iteration: start,
        gaussians_start,
        gaussians_end: trainer.num_gaussians(),
        iterations: opts.iterations,
        it_per_s: f64::from(n) / seconds.max(1e-9),
        ms_per_iteration: 1e3 * seconds / f64::from(n),
        host_ms_per_iteration: 1e3 * host_seconds / f64::from(n),
        submit_ms_per_iteration: 1e3 * submit_seconds / f64::from(n),
        compositor_gflop_per_s: compositor_gflop
            .filter(|_| phases_ms.compositor > 0.0)
            .map(|g| g / (phases_ms.compositor / 1e3)),
        compositor_gflop,
        phases_ms,
        peak_gpu_bytes: gpu.memory.peak_bytes(),
        peak_host_bytes: peak_host_bytes(),
        per_iteration: OpsPerIteration::from(ops, n),
        kernels,
    })
}

/// A scratch folder for downscaled images, removed on drop.
fn tempfile_dir(scene_dir: &Path) -> Result<tempfile::TempDir, StageError> {
    tempfile::Builder::new()
        .prefix("cocog-bench-")
        .tempdir()
        .map_err(|e| StageError::io(scene_dir, e))
}

/// The tensor-core block layout F's products use (`COCOG_COOP_BLOCK`, else the default).
impl BenchReport {
    /// A few aligned lines for a terminal.
    pub fn table(&self) -> String {
        let mut out = self.summary();
        if let (Some(g), Some(rate)) = (self.compositor_gflop, self.compositor_gflop_per_s) {
            let share = 100.0 * self.phases_ms.compositor / self.phases_ms.total.max(1e-9);
            let path = self.compositor_path.as_deref().unwrap_or("no compositor");
            let counted = if self.compositor_winograd {
                ", GFLOP counted as direct convolutions"
            } else {
                ""
            };
            let maps = if self.shader_f16 {
                "f16 maps"
            } else {
                "f32 maps"
            };
            out += &format!(
                "compositor F     {share:.0}% of the profiled step; {g:.2} GFLOP/iteration in its \
                 convolutions (forward + backward; {path}{counted}, {maps}), {rate:.2} GFLOP/s over the \
                 compositor phase\n"
            );
        }
        if !self.kernels.is_empty() {
            out += "GPU time per kernel (ms/iteration, passes/iteration):\n";
            for k in &self.kernels {
                out += &format!(
                    "  {:>9.3}  {:>5.1}  {}\n",
                    k.ms_per_iteration, k.passes_per_iteration, k.kernel
                );
            }
        }
        out
    }

    fn summary(&self) -> String {
        let p = &self.phases_ms;
        let mib = |b: u64| b as f64 / (1024.0 * 1024.0);
        let host = self
            .peak_host_bytes
            .map_or("unknown".to_owned(), |b| format!("{:.0} MiB", mib(b)));
        format!(
            "adapter          {} (float atomics: {}, subgroups: {}, f16: {})\n\
             tensor cores     {} (cooperative matrices; {})\n\
             source           {}\n\
             images           {} views at {}×{}{}\n\
             Gaussians        {} → {} (from iteration {})\n\
             method           {}\n\
             compositing      {}\n\
             shader checks    {}\n\
             throughput       {:.2} it/s, {:.1} ms/iteration ({} iterations)\n\
             host ms/it       {:.2} recording | {:.2} in queue.submit\n\
             profiled ms/it   forward {:.1} | backward {:.1} | optimizer {:.1} | density {:.1}{} | sum {:.1}\n\
             engine ops/it    {:.2} buffers created | {:.2} blocking reads | {:.2} submissions | {:.1} dispatches | {:.2} bind groups created\n\
             peak GPU memory  {:.1} MiB (engine buffers)\n\
             peak host memory {host}\n",
            self.adapter,
            yes_no(self.float_atomics),
            yes_no(self.subgroups),
            yes_no(self.shader_f16),
            self.cooperative_matrices,
            if self.cooperative_f16 {
                "enabled: COCOG_F_CONV=coop runs F on them"
            } else {
                "not enabled"
            },
            self.source,
            self.views,
            self.width,
            self.height,
            if self.bands > 1 {
                format!(
                    ", trained in {} bands of rows (past one buffer binding)",
                    self.bands
                )
            } else {
                String::new()
            },
            self.gaussians_start,
            self.gaussians_end,
            self.start_iteration,
            self.method,
            self.compositing,
            if self.shader_checks {
                "on (naga's index clamps, loop caps and division guards)"
            } else {
                "off (COCOG_SHADER_CHECKS=0)"
            },
            self.it_per_s,
            self.ms_per_iteration,
            self.iterations,
            self.host_ms_per_iteration,
            self.submit_ms_per_iteration,
            p.forward,
            p.backward,
            p.optimizer,
            p.density,
            if self.method == "cocog" {
                format!(
                    " | h_θ + expansion {:.1} | compositor {:.1}",
                    p.coc_net, p.compositor
                )
            } else {
                String::new()
            },
            p.total,
            self.per_iteration.buffers_created,
            self.per_iteration.blocking_reads,
            self.per_iteration.submissions,
            self.per_iteration.dispatches,
            self.per_iteration.bind_groups_created,
            mib(self.peak_gpu_bytes),
        )
    }
}

fn yes_no(b: bool) -> &'static str {
    if b { "yes" } else { "no" }
}

/// How the trainer's renderer composites (as the environment and the adapter set it), and the
/// forward's block side in a step's passes of `images` frames of `tiles`.
fn compositing_setting(
    renderer: &cocog_engine::Renderer,
    tiles: (u32, u32),
    images: u32,
) -> String {
    use cocog_engine::splat::RasterSplit;
    let blocks = renderer.blocks();
    let mut block = match std::env::var("COCOG_RASTER_BLOCK") {
        Ok(side) if blocks != cocog_engine::RasterBlocks::DEFAULT => {
            format!("{} (COCOG_RASTER_BLOCK={side})", blocks.describe())
        }
        _ => blocks.describe(),
    };
    if blocks.forward == cocog_engine::RasterBlocks::AUTO {
        let side = blocks.forward_side(tiles, images);
        block += &format!(" (this step's forward: {side}×{side})");
    }
    let split = match renderer.raster_split() {
        RasterSplit::Fixed(1) => "whole tile lists in the backward".to_owned(),
        RasterSplit::Fixed(n) => {
            format!("the backward walks each tile list in {n} chunks (COCOG_RASTER_SPLIT={n})")
        }
        RasterSplit::Auto => format!(
            "the backward splits tile lists into chunks for about {} workgroups \
             (COCOG_RASTER_SPLIT=auto, a GPU's default)",
            cocog_engine::splat::SPLIT_TARGET
        ),
    };
    let spans = if renderer.tile_spans() {
        &format!(
            "binning takes rectangle rows past {} tiles as spans",
            cocog_engine::splat::SCAN_WIDTH
        )
    } else {
        "binning tests every tile of each rectangle"
    };
    format!("{block}; {split}; {spans}")
}
