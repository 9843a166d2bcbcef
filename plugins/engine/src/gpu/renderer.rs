//! Orchestrates the forward and backward passes of a batch.

use super::GpuContext;
use super::batch::{Batch, ParamBuffers};
use super::kernel::{Kernel, shader};
use super::scan::PrefixSum;
use super::sort::{RadixSort, SortBuffers};
use super::state::{ForwardState, Gradients};
use crate::EngineError;
use crate::types::sh_coeffs_per_channel;

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Globals {
    num_gaussians: u32,
    num_images: u32,
    width: u32,
    height: u32,
    tiles_x: u32,
    tiles_y: u32,
    sh_coeffs: u32,
    pad: u32,
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct TileParams {
    num_gaussians: u32,
    num_intersections: u32,
    tiles_x: u32,
    tiles_per_image: u32,
    sentinel_tile: u32,
    pad: [u32; 3],
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct RasterParams {
    width: u32,
    height: u32,
    tiles_x: u32,
    tiles_y: u32,
}

/// Compiled pipelines of the engine; build once per device and reuse.
#[derive(Debug)]
pub struct Renderer {
    scan: PrefixSum,
    sort: RadixSort,
    project: Kernel,
    project_backward: Kernel,
    gather_counts: Kernel,
    emit_keys: Kernel,
    tile_ranges: Kernel,
    rasterize: Kernel,
    rasterize_backward: Kernel,
}

fn groups(n: u32) -> u32 {
    n.div_ceil(256)
}

impl Renderer {
    /// Uses the fastest gradient accumulation the device supports.
    pub fn new(ctx: &GpuContext) -> Self {
        Self::with_options(ctx, true, true)
    }

    /// Picks the gradient-accumulation variant: `native_atomics = false` forces the
    /// compare-exchange fallback and `subgroups = false` per-pixel atomics (to test those
    /// paths on devices that have more); `true` is ignored where the device lacks the feature.
    pub fn with_options(ctx: &GpuContext, native_atomics: bool, subgroups: bool) -> Self {
        let common = include_str!("project_common.wgsl");
        let tile_test = include_str!("tile_test.wgsl");
        let project = shader(
            ctx,
            "project",
            &format!("{common}\n{tile_test}\n{}", include_str!("project.wgsl")),
        );
        let project_bwd = shader(
            ctx,
            "project_backward",
            &format!("{common}\n{}", include_str!("project_backward.wgsl")),
        );
        let tiles = shader(
            ctx,
            "tiles",
            &format!("{tile_test}\n{}", include_str!("tiles.wgsl")),
        );
        let raster = shader(ctx, "rasterize", include_str!("rasterize.wgsl"));
        let atomics = if native_atomics && ctx.float_atomics {
            include_str!("atomic_native.wgsl")
        } else {
            include_str!("atomic_cas.wgsl")
        };
        let mut raster_bwd_src = include_str!("rasterize_backward.wgsl").to_owned();
        let flush = if subgroups && ctx.subgroups {
            raster_bwd_src = raster_bwd_src.replace(
                "// SUBGROUP_PARAM",
                "@builtin(subgroup_invocation_id) sg_lane: u32,",
            );
            include_str!("flush_subgroup.wgsl")
        } else {
            include_str!("flush_direct.wgsl")
        };
        let raster_bwd = shader(
            ctx,
            "rasterize_backward",
            &format!("{raster_bwd_src}\n{atomics}\n{flush}"),
        );
        Self {
            scan: PrefixSum::new(ctx),
            sort: RadixSort::new(ctx),
            project: Kernel::new(ctx, &project, "project"),
            project_backward: Kernel::new(ctx, &project_bwd, "project_backward"),
            gather_counts: Kernel::new(ctx, &tiles, "gather_counts"),
            emit_keys: Kernel::new(ctx, &tiles, "emit_keys"),
            tile_ranges: Kernel::new(ctx, &tiles, "tile_ranges"),
            rasterize: Kernel::new(ctx, &raster, "rasterize"),
            rasterize_backward: Kernel::new(ctx, &raster_bwd, "rasterize_backward"),
        }
    }

    fn globals(batch: &Batch) -> Globals {
        let (tiles_x, tiles_y) = batch.tiles();
        Globals {
            num_gaussians: batch.params.num_gaussians,
            num_images: batch.num_images(),
            width: batch.width(),
            height: batch.height(),
            tiles_x,
            tiles_y,
            sh_coeffs: sh_coeffs_per_channel(batch.params.sh_degree) as u32,
            pad: 0,
        }
    }

    fn raster_params(batch: &Batch) -> RasterParams {
        let (tiles_x, tiles_y) = batch.tiles();
        RasterParams {
            width: batch.width(),
            height: batch.height(),
            tiles_x,
            tiles_y,
        }
    }

    /// Renders every image of `batch`. Costs one GPU→CPU sync (the intersection count, which
    /// sizes the tile buffers); the images stay on the GPU.
    pub fn forward(&self, ctx: &GpuContext, batch: &Batch) -> Result<ForwardState, EngineError> {
        let n = batch.params.num_gaussians;
        let (tiles_x, tiles_y) = batch.tiles();
        let globals = ctx.uniform(&Self::globals(batch));
        let projected = ctx.storage("projected", u64::from(n) * 48);
        let rects = ctx.storage("rects", u64::from(n) * 16);
        let counts = ctx.storage("tile counts", u64::from(n) * 4);
        let mut by_depth = SortBuffers::new(
            ctx,
            ctx.storage("depth keys", u64::from(n) * 4),
            ctx.storage("depth ids", u64::from(n) * 4),
            n,
        );
        let offsets = ctx.storage("tile offsets", (u64::from(n) + 1) * 4);
        let p = &batch.params;
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        self.project.dispatch_1d(
            ctx,
            &mut encoder,
            &[
                (0, &globals),
                (1, &batch.image_infos),
                (2, &p.means),
                (3, &p.log_scales),
                (4, &p.quats),
                (5, &p.opacity_logits),
                (6, &p.sh),
                (7, &projected),
                (8, &rects),
                (9, &by_depth.keys),
                (10, &by_depth.values),
                (11, &counts),
            ],
            groups(n),
        );
        self.sort
            .encode(ctx, &self.scan, &mut encoder, &mut by_depth, n, 32);
        let tile_params = |num_intersections| TileParams {
            num_gaussians: n,
            num_intersections,
            tiles_x,
            tiles_per_image: tiles_x * tiles_y,
            sentinel_tile: tiles_x * tiles_y * batch.num_images(),
            pad: [0; 3],
        };
        let params = ctx.uniform(&tile_params(0));
        self.gather_counts.dispatch_1d(
            ctx,
            &mut encoder,
            &[
                (0, &params),
                (1, &by_depth.values),
                (2, &counts),
                (3, &offsets),
            ],
            groups(n + 1),
        );
        self.scan.encode(ctx, &mut encoder, &offsets, n + 1);
        ctx.queue.submit([encoder.finish()]);
        let total: Vec<u32> = ctx.read_at(&offsets, n as usize, 1)?;
        let k = total[0];

        let total_tiles = tiles_x * tiles_y * batch.num_images();
        let mut by_tile = SortBuffers::new(
            ctx,
            ctx.storage("tile keys", u64::from(k) * 4),
            ctx.storage("tile values", u64::from(k) * 4),
            k,
        );
        // One extra range for the sentinel tile, which no workgroup reads.
        let ranges = ctx.storage("tile ranges", (u64::from(total_tiles) + 1) * 8);
        let params = ctx.uniform(&tile_params(k));
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        self.emit_keys.dispatch_1d(
            ctx,
            &mut encoder,
            &[
                (0, &params),
                (1, &by_depth.values),
                (2, &counts),
                (3, &offsets),
                (4, &rects),
                (5, &by_tile.keys),
                (6, &by_tile.values),
                (8, &projected),
            ],
            groups(n),
        );
        // Keys run up to the sentinel `total_tiles` inclusive.
        let tile_bits = u32::BITS - total_tiles.leading_zeros();
        self.sort
            .encode(ctx, &self.scan, &mut encoder, &mut by_tile, k, tile_bits);
        self.tile_ranges.dispatch_1d(
            ctx,
            &mut encoder,
            &[(0, &params), (5, &by_tile.keys), (7, &ranges)],
            groups(k),
        );
        let pixels = batch.num_pixels();
        let state = ForwardState {
            rgba: ctx.storage("rgba", pixels * 16),
            depth: ctx.storage("depth", pixels * 4),
            final_t: ctx.storage("final transmittance", pixels * 4),
            last: ctx.storage("last contributor", pixels * 4),
            projected,
            ranges,
            tile_values: by_tile.values,
            num_intersections: k,
        };
        let raster = ctx.uniform(&Self::raster_params(batch));
        self.rasterize.dispatch(
            ctx,
            &mut encoder,
            &[
                (0, &raster),
                (1, &batch.backgrounds),
                (2, &state.ranges),
                (3, &state.tile_values),
                (4, &state.projected),
                (5, &state.rgba),
                (6, &state.depth),
                (7, &state.final_t),
                (8, &state.last),
            ],
            [tiles_x, tiles_y, batch.num_images()],
        );
        ctx.queue.submit([encoder.finish()]);
        Ok(state)
    }

    /// Gradients of a loss with respect to every parameter of `batch`, given the loss's
    /// gradients with respect to the forward outputs: `v_rgba` (rgb colour, alpha) and
    /// `v_depth`, both laid out like `state.rgba`/`state.depth`. No GPU→CPU sync.
    pub fn backward(
        &self,
        ctx: &GpuContext,
        batch: &Batch,
        state: &ForwardState,
        v_rgba: &wgpu::Buffer,
        v_depth: &wgpu::Buffer,
    ) -> Gradients {
        let n = batch.params.num_gaussians;
        let (tiles_x, tiles_y) = batch.tiles();
        let v_proj = ctx.storage("v_projected", u64::from(n) * 40);
        let grads = ParamBuffers::zeros_like(ctx, &batch.params);
        let raster = ctx.uniform(&Self::raster_params(batch));
        let globals = ctx.uniform(&Self::globals(batch));
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        self.rasterize_backward.dispatch(
            ctx,
            &mut encoder,
            &[
                (0, &raster),
                (1, &batch.backgrounds),
                (2, &state.ranges),
                (3, &state.tile_values),
                (4, &state.projected),
                (5, &state.final_t),
                (6, &state.last),
                (7, v_rgba),
                (8, v_depth),
                (9, &v_proj),
            ],
            [tiles_x, tiles_y, batch.num_images()],
        );
        let p = &batch.params;
        self.project_backward.dispatch_1d(
            ctx,
            &mut encoder,
            &[
                (0, &globals),
                (1, &batch.image_infos),
                (2, &p.means),
                (3, &p.log_scales),
                (4, &p.quats),
                (5, &p.opacity_logits),
                (6, &p.sh),
                (7, &v_proj),
                (8, &grads.means),
                (9, &grads.log_scales),
                (10, &grads.quats),
                (11, &grads.opacity_logits),
                (12, &grads.sh),
            ],
            groups(n),
        );
        ctx.queue.submit([encoder.finish()]);
        Gradients {
            params: grads,
            v_projected: v_proj,
        }
    }
}
