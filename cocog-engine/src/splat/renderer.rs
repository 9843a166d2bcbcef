//! Orchestrates the forward and backward passes of a batch.

use super::batch::{Batch, ParamBuffers};
use super::state::{ForwardState, Gradients};
use crate::EngineError;
use std::sync::OnceLock;

use crate::core::{Bind, GpuContext, Kernel, Recorder, Workspace, shader};
use crate::prims::{PrefixSum, RadixSort, SortBuffers, SortCount};
use crate::types::sh_coeffs_per_channel;

/// WGSL of `quat_to_rot(q: vec4<f32>) -> mat3x3<f32>`, the rotation of a unit (w, x, y, z)
/// quaternion, for shaders outside the engine that need the renderer's exact convention.
pub const QUAT_TO_ROT_WGSL: &str = include_str!("quat.wgsl");
/// `finite`, which project_common.wgsl and tile_test.wgsl both use.
pub const FINITE_WGSL: &str = include_str!("finite.wgsl");

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
    shared_rows: u32,
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
    pixels: u32,
    splits: u32,
    min_chunk: u32,
    pad: u32,
}

/// Compiled pipelines of the engine; build once per device and reuse.
#[derive(Debug)]
pub struct Renderer {
    scan: PrefixSum,
    // Separate so a profile splits their passes.
    depth_sort: RadixSort,
    tile_sort: RadixSort,
    project: Kernel,
    project_backward: Kernel,
    gather_counts: Kernel,
    emit_keys: Kernel,
    tile_ranges: Kernel,
    check_capacity: Kernel,
    /// The compositing forward, made on first use: `[side 8][split]`, where a split one also
    /// records chunk state for a split backward (unsplit, the inner loop carries no boundary
    /// test).
    rasterize: [[OnceLock<Kernel>; 2]; 2],
    /// The compositing backward's source and its two builds, made on first use: with the depth
    /// channel (`[1]`) and without it (`[0]`).
    rasterize_backward_src: String,
    rasterize_backward: [OnceLock<Kernel>; 2],
    /// Overrides the device's binding limit (tests of the banded paths at small sizes).
    binding_limit: Option<u64>,
    /// The compositing forward's and backward's workgroups: blocks of a 16×16 tile, 8 or 16
    /// pixels a side (the forward's also `RasterBlocks::AUTO`).
    blocks: RasterBlocks,
    /// How many chunks the compositing backward splits each tile's list into.
    raster_split: RasterSplit,
    /// Whether the binning kernels take wide rows as spans.
    tile_spans: bool,
}

/// How many workgroups walk each tile's list in the compositing backward, each a chunk of it
/// (the forward records where each chunk starts). One long list is otherwise one workgroup's
/// serial walk, and a small frame has too few tiles to fill a GPU.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RasterSplit {
    /// Every list in this many chunks of ⌈length / N⌉ Gaussians, the last one shorter (1:
    /// unsplit), however short.
    Fixed(u32),
    /// Enough chunks that a backward dispatch (all of a batch's images) has about
    /// `SPLIT_TARGET` workgroups, at most `MAX_SPLIT`, none but a list's last shorter than
    /// `AUTO_MIN_CHUNK` Gaussians: a chunk's workgroup pays its set-up (per-pixel loads,
    /// barriers) however few Gaussians it walks.
    Auto,
}

impl RasterSplit {
    /// The shortest chunk but a list's last.
    fn min_chunk(self) -> u32 {
        match self {
            Self::Fixed(_) => 1,
            Self::Auto => AUTO_MIN_CHUNK,
        }
    }
}

/// Shortest chunk `RasterSplit::Auto` cuts a list into.
pub const AUTO_MIN_CHUNK: u32 = 64;

/// Workgroups `RasterSplit::Auto` aims a compositing backward's dispatch at.
pub const SPLIT_TARGET: u32 = 2048;
/// Most chunks per tile list.
pub const MAX_SPLIT: u32 = 16;

/// How the compositing backward walks its tile lists on `ctx`'s adapter: `COCOG_RASTER_SPLIT=N`
/// (1 to `MAX_SPLIT`) or `auto` where set, else `Auto` on a GPU and whole lists on a CPU
/// adapter. On an H200 the split took the 3dgs step at 100×75 from 4.6 to 1.7 ms and at
/// 400×300 from 1.5 to 1.3 ms (a short frame's few tiles leave most of a GPU idle while each
/// workgroup walks a whole list); on lavapipe's two cores it cost 5–10 %.
pub fn raster_split_for(ctx: &GpuContext) -> RasterSplit {
    let default = if ctx.is_cpu() {
        RasterSplit::Fixed(1)
    } else {
        RasterSplit::Auto
    };
    crate::core::env_switch(
        "COCOG_RASTER_SPLIT",
        &format!("auto or 1 to {MAX_SPLIT}"),
        "the adapter's default stays",
        default,
        |value| match value {
            "auto" => Some(RasterSplit::Auto),
            n => n
                .parse::<u32>()
                .ok()
                .filter(|n| (1..=MAX_SPLIT).contains(n))
                .map(RasterSplit::Fixed),
        },
    )
}

/// Whether the projection and the key emission take a rectangle's rows wider than
/// `SCAN_WIDTH` tiles as spans (tile_test.wgsl's `row_span`: a seed, two guessed ends and a
/// few tile tests each, the same tiles) rather than testing every tile: `COCOG_TILE_SPANS=0`
/// or `1` where set, else spans on a GPU and the scan on a CPU adapter. On an H100
/// (2026-11-28) spans halved the two kernels at 400×300 (sharp-dev after 30000 iterations,
/// 110k Gaussians: 0.151 + 0.111 → 0.074 + 0.075 ms) and took its 3dgs step from 513 to 548
/// it/s; at 100×75 they changed nothing. On lavapipe the two kernels took 7.8–9.9 ms with
/// spans against 4.6–6.9 without. Anything but 0 or 1 is said on stderr and ignored.
fn tile_spans(ctx: &GpuContext) -> bool {
    crate::core::env_choice(
        "COCOG_TILE_SPANS",
        &[("0", false), ("1", true)],
        "the adapter's default stays",
        !ctx.is_cpu(),
    )
}

/// Rows up to this many tiles are scanned: a span costs a seed, four end tests and the guesses'
/// arithmetic, about eight tests. Over a sharp-dev model's rectangles at 400×300 this width
/// left the slowest of each 32 Gaussians 26 % fewer tests (4: 18 %, 12: 20 %).
pub const SCAN_WIDTH: u32 = 8;

/// What the projection's forward and backward share: bindings, cameras and the forward maths.
fn projection_common() -> String {
    format!(
        "{QUAT_TO_ROT_WGSL}\n{FINITE_WGSL}\n{}",
        include_str!("project_common.wgsl")
    )
}

/// The projection and the tile-binning kernels (gather_counts, emit_keys, tile_ranges,
/// check_capacity), taking wide rows as spans or not.
fn binning_kernels(ctx: &GpuContext, spans: bool) -> (Kernel, Kernel, Kernel, Kernel, Kernel) {
    let tile_test = format!(
        "const TILE_SPANS: bool = {spans};\nconst SCAN_WIDTH: u32 = {SCAN_WIDTH}u;\n{}",
        include_str!("tile_test.wgsl")
    );
    let project = shader(
        ctx,
        "project",
        &format!(
            "{}\n{tile_test}\n{}",
            projection_common(),
            include_str!("project.wgsl")
        ),
    );
    let tiles = shader(
        ctx,
        "tiles",
        &format!("{FINITE_WGSL}\n{tile_test}\n{}", include_str!("tiles.wgsl")),
    );
    (
        Kernel::new(ctx, &project, "project"),
        Kernel::new(ctx, &tiles, "gather_counts"),
        Kernel::new(ctx, &tiles, "emit_keys"),
        Kernel::new(ctx, &tiles, "tile_ranges"),
        Kernel::new(ctx, &tiles, "check_capacity"),
    )
}

fn groups(n: u32) -> u32 {
    n.div_ceil(256)
}

/// The side of the pixel block one workgroup of the compositing forward and of its backward
/// composites: 16 (a tile) or 8 (a quarter of one, each walking the tile's whole list); for the
/// forward also `AUTO`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RasterBlocks {
    pub forward: u32,
    pub backward: u32,
}

impl RasterBlocks {
    /// The forward's side chosen per pass: 8 where a batch has fewer than `SPLIT_TARGET` tiles,
    /// else 16.
    pub const AUTO: u32 = 0;

    /// Forward in 8×8 blocks on frames of few tiles, backward in 16×16 tiles. On an H200 the
    /// forward's 8×8 blocks took 0.685 ms against 0.846 at 100×75 (35 tiles) and 0.130 against
    /// 0.152 at 400×300 (475 tiles; dev-table, 57k Gaussians), and the cocog step's forward
    /// (six renders at 100×75) 0.745 against 0.910: with fewer tiles than the GPU has room for
    /// workgroups, four blocks per tile fill it, and a block stops walking once its own 64
    /// pixels are opaque, not the tile's 256. Past that count every block walks its tile's list
    /// again for nothing (not measured there), so larger batches keep whole tiles. The
    /// backward's workgroups come from splitting lists (`RasterSplit`), which beat 8×8 blocks
    /// (0.290 against 0.421 ms at 400×300). A pixel's result is the same either way, and the
    /// backward reads only per-pixel state, so the two sides need not agree.
    pub const DEFAULT: Self = Self {
        forward: Self::AUTO,
        backward: 16,
    };

    /// The forward's side for a batch of `images` frames of `tiles` (x, y) tiles.
    pub fn forward_side(self, tiles: (u32, u32), images: u32) -> u32 {
        if self.forward != Self::AUTO {
            return self.forward;
        }
        if u64::from(tiles.0) * u64::from(tiles.1) * u64::from(images) < u64::from(SPLIT_TARGET) {
            8
        } else {
            16
        }
    }

    /// Both sides in blocks of `side` (8, else 16).
    pub fn both(side: u32) -> Self {
        let side = if side == 8 { 8 } else { 16 };
        Self {
            forward: side,
            backward: side,
        }
    }

    /// `COCOG_RASTER_BLOCK=8` or `16` puts both sides in blocks of that side (to time them
    /// against the default); unset, `DEFAULT`; anything else is said on stderr and ignored.
    pub fn from_env() -> Self {
        crate::core::env_choice(
            "COCOG_RASTER_BLOCK",
            &[("8", Self::both(8)), ("16", Self::both(16))],
            "the default stays",
            Self::DEFAULT,
        )
    }

    /// Said by `cocog bench`.
    pub fn describe(self) -> String {
        let side = |s: u32| match s {
            8 => "8×8 blocks of each 16×16 tile".to_owned(),
            Self::AUTO => format!(
                "8×8 blocks of each 16×16 tile below {SPLIT_TARGET} tiles per pass, else 16×16 tiles"
            ),
            _ => "16×16 tiles".to_owned(),
        };
        if self.forward == self.backward {
            side(self.forward)
        } else {
            format!(
                "forward in {}, backward in {}",
                side(self.forward),
                side(self.backward)
            )
        }
    }
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
        let project_bwd = shader(
            ctx,
            "project_backward",
            &format!(
                "{}\n{}",
                projection_common(),
                include_str!("project_backward.wgsl")
            ),
        );
        let spans = tile_spans(ctx);
        let (project, gather_counts, emit_keys, tile_ranges, check_capacity) =
            binning_kernels(ctx, spans);
        let blocks = RasterBlocks::from_env();
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
        let rasterize_backward_src = format!("{raster_bwd_src}\n{atomics}\n{flush}");
        Self {
            scan: PrefixSum::new(ctx),
            depth_sort: RadixSort::new(ctx, "depth"),
            tile_sort: RadixSort::new(ctx, "tiles"),
            project,
            project_backward: Kernel::new(ctx, &project_bwd, "project_backward"),
            gather_counts,
            emit_keys,
            tile_ranges,
            check_capacity,
            rasterize: Default::default(),
            rasterize_backward_src,
            rasterize_backward: Default::default(),
            binding_limit: None,
            blocks,
            raster_split: raster_split_for(ctx),
            tile_spans: spans,
        }
    }

    /// The projection and the key emission taking wide rows as spans (`true`) or testing every
    /// tile, whatever `COCOG_TILE_SPANS` says.
    pub fn with_tile_spans(mut self, ctx: &GpuContext, spans: bool) -> Self {
        (
            self.project,
            self.gather_counts,
            self.emit_keys,
            self.tile_ranges,
            self.check_capacity,
        ) = binning_kernels(ctx, spans);
        self.tile_spans = spans;
        self
    }

    /// Whether the projection and the key emission take rows wider than `SCAN_WIDTH` tiles
    /// as spans.
    pub fn tile_spans(&self) -> bool {
        self.tile_spans
    }

    /// Plans for at most `bytes` per buffer binding instead of the device's limit.
    pub fn with_binding_limit(mut self, bytes: u64) -> Self {
        self.binding_limit = Some(bytes);
        self
    }

    /// Bytes one buffer binding may span: the device's limit unless overridden.
    pub fn binding_limit(&self, ctx: &GpuContext) -> u64 {
        self.binding_limit.unwrap_or_else(|| ctx.binding_limit())
    }

    /// Most (tile, Gaussian) intersections one forward pass holds: its key and value
    /// buffers (a u32 each) must each fit one binding.
    pub fn max_intersections(&self, ctx: &GpuContext) -> u32 {
        u32::try_from(self.binding_limit(ctx) / 4).unwrap_or(u32::MAX)
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
            shared_rows: batch.params.shared_rows,
        }
    }

    fn raster_params(batch: &Batch, splits: u32, min_chunk: u32) -> RasterParams {
        let (tiles_x, tiles_y) = batch.tiles();
        RasterParams {
            width: batch.width(),
            height: batch.height(),
            tiles_x,
            tiles_y,
            // Every per-pixel buffer fits a binding, and the renderer bands frames that would not.
            pixels: u32::try_from(batch.num_pixels()).expect("a batch's pixels fit in u32"),
            splits,
            min_chunk,
            pad: 0,
        }
    }

    /// Chunks per tile list for `batch`: as asked, within what one binding of the chunk state
    /// (16 bytes per pixel and chunk) and the grid's x (blocks in a row × chunks) allow.
    fn splits(&self, ctx: &GpuContext, batch: &Batch) -> u32 {
        let (tiles_x, tiles_y) = batch.tiles();
        let per_tile = 16 / self.blocks.backward;
        let wanted = match self.raster_split {
            RasterSplit::Fixed(n) => n,
            RasterSplit::Auto => {
                let groups = tiles_x * tiles_y * per_tile * per_tile * batch.num_images();
                SPLIT_TARGET.div_ceil(groups.max(1))
            }
        };
        let by_binding = self.binding_limit(ctx) / (16 * batch.num_pixels().max(1));
        let by_grid =
            ctx.device.limits().max_compute_workgroups_per_dimension / (tiles_x * per_tile).max(1);
        wanted
            .min(MAX_SPLIT)
            .min(u32::try_from(by_binding).unwrap_or(u32::MAX))
            .min(by_grid)
            .max(1)
    }

    /// Renders every image of `batch` into buffers of its own. Sizes the intersection
    /// buffers by reading the count back (one or two blocking reads); the images stay on the
    /// GPU. Training loops use `encode_forward`, which never waits. Fails with
    /// `TooManyIntersections` when the intersections outgrow a binding.
    pub fn forward(&self, ctx: &GpuContext, batch: &Batch) -> Result<ForwardState, EngineError> {
        self.forward_split(ctx, batch, true)
    }

    /// `forward`; without `split`, no chunk state for a backward (frames rendered to be seen).
    pub(crate) fn forward_split(
        &self,
        ctx: &GpuContext,
        batch: &Batch,
        split: bool,
    ) -> Result<ForwardState, EngineError> {
        let mut ws = Workspace::default();
        let most = self.max_intersections(ctx);
        let mut capacity = batch
            .params
            .num_gaussians
            .saturating_mul(4)
            .max(1024)
            .min(most);
        loop {
            let mut rec = ctx.recorder();
            let splits = if split { self.splits(ctx, batch) } else { 1 };
            let mut state = self.encode_forward_in(&mut rec, &mut ws, batch, capacity, splits);
            rec.submit();
            let [_, k]: [u32; 2] = ctx
                .read(&state.status, 2)?
                .try_into()
                .map_err(|_| EngineError::Readback("status has two words".into()))?;
            if k <= capacity {
                state.num_intersections = k;
                return Ok(state);
            }
            if k > most {
                return Err(EngineError::TooManyIntersections { needed: k, most });
            }
            capacity = k;
        }
    }

    /// Records the forward pass of `batch` into `rec`, with every buffer from `ws` and room
    /// for `capacity` (tile, Gaussian) intersections. No read-back: the true count and an
    /// overflow flag land in `state.status` on the GPU ([overflowed, count]); an overflowed
    /// pass rendered only part of its intersections and must be redone with more room.
    pub fn encode_forward(
        &self,
        rec: &mut Recorder,
        ws: &mut Workspace,
        batch: &Batch,
        capacity: u32,
    ) -> ForwardState {
        let splits = self.splits(rec.ctx(), batch);
        self.encode_forward_in(rec, ws, batch, capacity, splits)
    }

    /// `encode_forward` recording chunk state for a backward of `splits` chunks per list.
    fn encode_forward_in(
        &self,
        rec: &mut Recorder,
        ws: &mut Workspace,
        batch: &Batch,
        capacity: u32,
        splits: u32,
    ) -> ForwardState {
        let ctx = rec.ctx();
        let n = batch.params.num_gaussians;
        let (tiles_x, tiles_y) = batch.tiles();
        let globals = rec.uniform(&Self::globals(batch));
        let projected = ws.zeroed(rec, "projected", u64::from(n) * 48);
        let rects = ws.buffer(ctx, "rects", u64::from(n) * 16);
        let counts = ws.buffer(ctx, "tile counts", u64::from(n) * 4);
        let mut by_depth = SortBuffers {
            keys: ws.buffer(ctx, "depth keys", u64::from(n) * 4),
            values: ws.buffer(ctx, "depth ids", u64::from(n) * 4),
            keys_tmp: ws.buffer(ctx, "depth keys tmp", u64::from(n) * 4),
            values_tmp: ws.buffer(ctx, "depth ids tmp", u64::from(n) * 4),
        };
        let offsets = ws.buffer(ctx, "tile offsets", (u64::from(n) + 1) * 4);
        let p = &batch.params;
        self.project.dispatch_1d(
            rec,
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
        // Culled Gaussians (no tile: off-frame, behind the camera, too faint) carry the largest
        // key and are dropped by the sort's first pass: the later passes and the binning see
        // the visible ones only.
        let visible = ws.buffer(ctx, "visible count", 16);
        self.depth_sort.encode(
            rec,
            ws,
            &self.scan,
            &mut by_depth,
            SortCount::Host(n),
            32,
            Some(&visible),
        );
        let total_tiles = tiles_x * tiles_y * batch.num_images();
        let params = rec.uniform(&TileParams {
            num_gaussians: n,
            num_intersections: capacity,
            tiles_x,
            tiles_per_image: tiles_x * tiles_y,
            sentinel_tile: total_tiles,
            pad: [0; 3],
        });
        self.gather_counts.dispatch_1d(
            rec,
            &[
                (0, &params),
                (1, &by_depth.values),
                (2, &counts),
                (3, &offsets),
                (10, &visible),
            ],
            groups(n + 1),
        );
        self.scan.encode(rec, ws, &offsets, n + 1);
        let status = ws.buffer(ctx, "forward status", 8);
        self.check_capacity
            .dispatch_1d(rec, &[(0, &params), (3, &offsets), (9, &status)], 1);
        let mut by_tile = SortBuffers {
            keys: ws.buffer(ctx, "tile keys", u64::from(capacity) * 4),
            values: ws.buffer(ctx, "tile values", u64::from(capacity) * 4),
            keys_tmp: ws.buffer(ctx, "tile keys tmp", u64::from(capacity) * 4),
            values_tmp: ws.buffer(ctx, "tile values tmp", u64::from(capacity) * 4),
        };
        // One extra range for the sentinel tile, which no workgroup reads; tiles no
        // Gaussian touches keep the cleared (0, 0).
        let ranges = ws.zeroed(rec, "tile ranges", (u64::from(total_tiles) + 1) * 8);
        self.emit_keys.dispatch_1d(
            rec,
            &[
                (0, &params),
                (1, &by_depth.values),
                (2, &counts),
                (3, &offsets),
                (4, &rects),
                (5, &by_tile.keys),
                (6, &by_tile.values),
                (8, &projected),
                (10, &visible),
            ],
            groups(n),
        );
        // Keys run up to the sentinel `total_tiles` inclusive.
        let tile_bits = u32::BITS - total_tiles.leading_zeros();
        let count = SortCount::Gpu {
            capacity,
            buffer: &offsets,
            index: n,
        };
        self.tile_sort
            .encode(rec, ws, &self.scan, &mut by_tile, count, tile_bits, None);
        self.tile_ranges.dispatch_1d(
            rec,
            &[
                (0, &params),
                (3, &offsets),
                (5, &by_tile.keys),
                (7, &ranges),
            ],
            groups(capacity),
        );
        let pixels = batch.num_pixels();
        // Unsplit, nothing reads the chunk state: a word each keeps the bindings valid.
        let chunk_pixels = if splits > 1 { pixels } else { 1 };
        let state = ForwardState {
            rgba: ws.buffer(ctx, "rgba", pixels * 16),
            depth: ws.buffer(ctx, "depth", pixels * 4),
            final_t: ws.buffer(ctx, "final transmittance", pixels * 4),
            last: ws.buffer(ctx, "last contributor", pixels * 4),
            projected,
            ranges,
            tile_values: by_tile.values,
            status,
            num_intersections: capacity,
            splits,
            chunk_state: ws.buffer(ctx, "chunk state", chunk_pixels * 16 * u64::from(splits)),
            chunk_depth: ws.buffer(ctx, "chunk depth", chunk_pixels * 4 * u64::from(splits)),
            min_chunk: self.raster_split.min_chunk(),
        };
        let raster = rec.uniform(&Self::raster_params(batch, splits, state.min_chunk));
        let side = self.blocks.forward_side(batch.tiles(), batch.num_images());
        let per_tile = 16 / side;
        let rasterize = self.rasterize[usize::from(side == 8)][usize::from(splits > 1)]
            .get_or_init(|| Self::rasterize_kernel(ctx, side, splits > 1));
        rasterize.dispatch(
            rec,
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
                (9, &state.chunk_state),
                (10, &state.chunk_depth),
            ],
            [tiles_x * per_tile, tiles_y * per_tile, batch.num_images()],
        );
        state
    }

    /// The compositing forward and backward in workgroups of these blocks, where the default
    /// (`RasterBlocks::from_env`) is not wanted. A side other than 8 is taken as 16, but the
    /// forward's `AUTO`.
    pub fn with_raster_blocks(mut self, blocks: RasterBlocks) -> Self {
        let forward = if blocks.forward == RasterBlocks::AUTO {
            RasterBlocks::AUTO
        } else {
            RasterBlocks::both(blocks.forward).forward
        };
        self.blocks = RasterBlocks {
            forward,
            backward: RasterBlocks::both(blocks.backward).backward,
        };
        self.rasterize_backward = Default::default();
        self
    }

    /// The blocks the compositing forward and backward run in.
    pub fn blocks(&self) -> RasterBlocks {
        self.blocks
    }

    /// How the compositing backward splits tile lists.
    pub fn raster_split(&self) -> RasterSplit {
        self.raster_split
    }

    /// Splits the compositing backward's tile lists as `split` says, where the default
    /// (`raster_split_for`) is not wanted.
    pub fn with_raster_split(mut self, split: RasterSplit) -> Self {
        self.raster_split = split;
        self
    }

    fn rasterize_kernel(ctx: &GpuContext, block: u32, split: bool) -> Kernel {
        let src = format!(
            "const SUB: u32 = {block}u;\nconst SPLIT: bool = {split};\n{}",
            include_str!("rasterize.wgsl")
        );
        Kernel::new(ctx, &shader(ctx, "rasterize", &src), "rasterize")
    }

    /// The compositing backward, with or without the depth channel.
    fn rasterize_backward(&self, ctx: &GpuContext, depth: bool) -> &Kernel {
        self.rasterize_backward[usize::from(depth)].get_or_init(|| {
            let sub = self.blocks.backward;
            let prelude = if depth {
                "const DEPTH_GRAD: bool = true;\n\
                 @group(0) @binding(8) var<storage, read> v_depth: array<f32>;\n\
                 fn depth_grad(pix: u32) -> f32 { return v_depth[pix]; }"
            } else {
                "const DEPTH_GRAD: bool = false;\n\
                 fn depth_grad(pix: u32) -> f32 { return 0.0; }"
            };
            let label = if depth {
                "rasterize_backward"
            } else {
                "rasterize_backward (no depth)"
            };
            let src = format!(
                "const SUB: u32 = {sub}u;\n{prelude}\n{}",
                self.rasterize_backward_src
            );
            Kernel::labelled(ctx, &shader(ctx, label, &src), "rasterize_backward", label)
        })
    }

    /// Gradients of a loss with respect to every parameter of `batch`, given the loss's
    /// gradients with respect to the forward outputs: `v_rgba` (rgb colour, alpha) and
    /// `v_depth`, both laid out like `state.rgba`/`state.depth`; `None` where the loss does
    /// not look at depth, which compiles the depth channel out. No GPU→CPU sync.
    pub fn backward(
        &self,
        ctx: &GpuContext,
        batch: &Batch,
        state: &ForwardState,
        v_rgba: &wgpu::Buffer,
        v_depth: Option<&wgpu::Buffer>,
    ) -> Gradients {
        let mut rec = ctx.recorder();
        let grads = self.encode_backward(
            &mut rec,
            &mut Workspace::default(),
            batch,
            state,
            v_rgba,
            v_depth,
        );
        rec.submit();
        grads
    }

    /// Records `backward` into `rec`, with the gradient buffers from `ws`.
    pub fn encode_backward(
        &self,
        rec: &mut Recorder,
        ws: &mut Workspace,
        batch: &Batch,
        state: &ForwardState,
        v_rgba: &wgpu::Buffer,
        v_depth: Option<&wgpu::Buffer>,
    ) -> Gradients {
        let ctx = rec.ctx();
        let n = batch.params.num_gaussians;
        let (tiles_x, tiles_y) = batch.tiles();
        let v_proj = ws.zeroed(rec, "v_projected", u64::from(n) * 40);
        let grads = ParamBuffers::gradients_in(ctx, ws, &batch.params);
        let raster = rec.uniform(&Self::raster_params(batch, state.splits, state.min_chunk));
        let globals = rec.uniform(&Self::globals(batch));
        let mut binds: Vec<(u32, &dyn Bind)> = vec![
            (0, &raster),
            (1, &batch.backgrounds),
            (2, &state.ranges),
            (3, &state.tile_values),
            (4, &state.projected),
            (5, &state.final_t),
            (6, &state.last),
            (7, v_rgba),
            (9, &v_proj),
            (10, &state.chunk_state),
            (11, &state.chunk_depth),
        ];
        if let Some(v_depth) = v_depth {
            binds.push((8, v_depth));
        }
        let per_tile = 16 / self.blocks.backward;
        self.rasterize_backward(ctx, v_depth.is_some()).dispatch(
            rec,
            &binds,
            [
                tiles_x * per_tile * state.splits,
                tiles_y * per_tile,
                batch.num_images(),
            ],
        );
        let p = &batch.params;
        self.project_backward.dispatch_1d(
            rec,
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
        Gradients {
            params: grads,
            v_projected: v_proj,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::{RasterBlocks, SPLIT_TARGET};

    #[test]
    fn forward_blocks_follow_the_tile_count() {
        let auto = RasterBlocks::DEFAULT;
        // dev-table: 100×75 (7 × 5 tiles), six renders of it, 400×300 (25 × 19).
        assert_eq!(auto.forward_side((7, 5), 1), 8);
        assert_eq!(auto.forward_side((7, 5), 6), 8);
        assert_eq!(auto.forward_side((25, 19), 1), 8);
        // The cocog step's six renders at 400×300, and a 1080p frame: whole tiles.
        assert_eq!(auto.forward_side((25, 19), 6), 16);
        assert_eq!(auto.forward_side((120, 68), 1), 16);
        assert_eq!(auto.forward_side((SPLIT_TARGET, 1), 1), 16);
        assert_eq!(auto.forward_side((SPLIT_TARGET - 1, 1), 1), 8);
        assert_eq!(auto.backward, 16);
        for side in [8, 16] {
            let both = RasterBlocks::both(side);
            assert_eq!(both.forward_side((7, 5), 1), side);
            assert_eq!(both.forward_side((120, 68), 1), side);
        }
    }
}
