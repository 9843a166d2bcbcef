//! One tiled matrix-product kernel (gemm.wgsl) specialised per problem by a WGSL prelude that
//! says how to read A and B and where C goes: the MLP h_θ's layers and their gradients, and
//! F's convolutions as implicit GEMMs. Long reductions (weight gradients sum over every
//! Gaussian or pixel) split K across workgroups and add the partial products in a fixed order,
//! so results are reproducible.

use crate::core::{Bind, CoopFragments, GpuContext, Kernel, Recorder, Workspace, shader};

/// Workgroups along x before the tile grid folds into y.
const MAX_GRID_X: u32 = 65_535;
/// K per split is at least this, so each workgroup amortises its tile loads; splits are added
/// until the grid has about `TARGET_INVOCATIONS`. Counted in invocations, not workgroups: a
/// 64 × 16 weight-gradient tile has 64 of them, and 256 such workgroups filled 6 % of an
/// H200's (F's 5×5 weight gradient ran at 1.4 TFLOP/s there).
const MIN_K_SPLIT: u32 = 256;
const TARGET_INVOCATIONS: u32 = 1 << 17;

/// The block of C one workgroup computes: its threads as rows × columns, each computing 4×4
/// values of C. Small problems (a weight gradient of 16 × 76) want small tiles, long ones
/// (a layer over every Gaussian) big square ones.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct GemmTile {
    pub thread_rows: u32,
    pub thread_cols: u32,
}

impl GemmTile {
    /// 64 × 64 from 256 threads.
    pub const SQUARE: Self = Self::new(16, 16);

    pub const fn new(thread_rows: u32, thread_cols: u32) -> Self {
        Self {
            thread_rows,
            thread_cols,
        }
    }

    /// The tile that wastes least on an `m` × `n` result (ties: more threads), among
    /// workgroups of 64 or 256 threads.
    pub fn for_shape(m: u32, n: u32) -> Self {
        const CHOICES: [GemmTile; 8] = [
            GemmTile::new(16, 16),
            GemmTile::new(4, 64),
            GemmTile::new(2, 128),
            GemmTile::new(64, 4),
            GemmTile::new(8, 8),
            GemmTile::new(4, 16),
            GemmTile::new(2, 32),
            GemmTile::new(16, 4),
        ];
        let padded = |t: &GemmTile| {
            let (bm, bn) = (4 * t.thread_rows, 4 * t.thread_cols);
            u64::from(m.div_ceil(bm) * bm) * u64::from(n.div_ceil(bn) * bn)
        };
        let mut best = CHOICES[0];
        for t in CHOICES {
            // Within 10 % of the least padding, prefer the bigger workgroup (listed first).
            if padded(&t) * 10 < padded(&best) * 9 {
                best = t;
            }
        }
        best
    }

    /// Rows and columns of the tile, and the depth of a staged slice (so both slices fit the
    /// 16 KiB of workgroup memory every adapter has).
    fn dims(self) -> (u32, u32, u32) {
        let (bm, bn) = (4 * self.thread_rows, 4 * self.thread_cols);
        let bk = if bm + bn > 256 { 8 } else { 16 };
        (bm, bn, bk)
    }
}

/// How the problem's operands lie in memory and whether K is split.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct GemmLayout {
    /// A(m, k) is contiguous along k (row-major A), else along m.
    pub a_k_fast: bool,
    /// B(k, n) is contiguous along k (B stored transposed), else along n.
    pub b_k_fast: bool,
    /// Sum K in independent ranges, then reduce (for K ≫ M·N).
    pub split_k: bool,
    /// B's last column is all ones (a bias's gradient): never loaded, its products are A's row
    /// sums, which the first column of tiles adds on the side. Without it, a 64-wide layer's
    /// bias made N = 65 and a second column of tiles 98 % padding.
    pub ones_column: bool,
    pub tile: GemmTile,
}

/// M, N, K (per batch), the batch count and up to 10 problem parameters (the prelude reads
/// them as `gemm.u0`…`gemm.u9`). Without split K, batches are independent products; with it,
/// the sum runs over every batch too.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct GemmShape {
    pub m: u32,
    pub n: u32,
    pub k: u32,
    pub batches: u32,
    pub params: [u32; 10],
}

impl Default for GemmShape {
    fn default() -> Self {
        Self {
            m: 0,
            n: 0,
            k: 0,
            batches: 1,
            params: [0; 10],
        }
    }
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Dims {
    m: u32,
    n: u32,
    k: u32,
    k_split: u32,
    parts: u32,
    batches: u32,
    params: [u32; 10],
}

/// A compiled problem. Binding 0 is the dimensions' uniform and, with `split_k`, binding 1 the
/// partial products; the prelude's own bindings start at 2.
#[derive(Debug)]
pub struct Gemm {
    layout: GemmLayout,
    tile: Kernel,
    reduce: Option<Kernel>,
    /// The tile kernel is gemm_coop.wgsl's, on these fragments in this layout.
    cooperative: Option<(CoopFragments, CoopBlock)>,
}

/// Powers of two that scale A and B before gemm_coop.wgsl rounds them to f16 (undone on C), so
/// small operands such as loss gradients stay in f16's normal range.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OperandScales {
    pub a: f32,
    pub b: f32,
}

impl OperandScales {
    pub const NONE: Self = Self { a: 1.0, b: 1.0 };
}

/// How gemm_coop.wgsl lays a block of C over a workgroup: `subgroups` (along M, along N), each
/// accumulating `fragments` (along M, along N), from staged slices `depth` fragments deep;
/// with `prefetch`, each invocation loads its share of the next slice into registers before
/// the current slice's products, so the loads' latency overlaps them; `pad` halves more per
/// staged row skew the rows across workgroup-memory banks (unpadded, NVIDIA's slices have rows
/// of 64 bytes in A and 128 or 256 in B, which start in the same banks, so a fragment's rows
/// conflict; 8 halves keep every row 16-byte aligned, as cooperative loads require). Bigger blocks share each
/// staged slice among more products; more fragments per subgroup give the tensor cores more
/// work per load. Which is fastest is the GPU's to say (`cargo bench
/// --bench gemm` times every named layout), so the default stays the first one until a device
/// has measured them.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CoopBlock {
    pub subgroups: (u32, u32),
    pub fragments: (u32, u32),
    pub depth: u32,
    pub prefetch: bool,
    pub pad: u32,
}

impl CoopBlock {
    /// 4 × 4 fragments from four subgroups of 2 × 2, slices 2 deep (64 × 64 × 32 on NVIDIA).
    pub const SQUARE: Self = Self::new((2, 2), (2, 2), 2);

    /// The layouts `COCOG_COOP_BLOCK` names, as fragments of C per block (rows × columns; F's
    /// products all have M = 64, 4 fragments on NVIDIA), after `k` the slice's depth, `p`
    /// for prefetching and `s` for skewed (padded) rows.
    pub const NAMED: [(&'static str, Self); 11] = [
        ("4x4", Self::SQUARE),
        ("4x8", Self::new((1, 4), (4, 2), 2)),
        ("4x16", Self::new((1, 4), (4, 4), 2)),
        ("4x8k4", Self::new((1, 4), (4, 2), 4)),
        ("8x8", Self::new((2, 4), (4, 2), 2)),
        ("4x4p", Self::SQUARE.prefetching()),
        ("4x8p", Self::new((1, 4), (4, 2), 2).prefetching()),
        ("4x4s", Self::SQUARE.skewed()),
        ("4x8s", Self::new((1, 4), (4, 2), 2).skewed()),
        ("4x4ps", Self::SQUARE.prefetching().skewed()),
        ("4x8ps", Self::new((1, 4), (4, 2), 2).prefetching().skewed()),
    ];

    pub const fn new(subgroups: (u32, u32), fragments: (u32, u32), depth: u32) -> Self {
        Self {
            subgroups,
            fragments,
            depth,
            prefetch: false,
            pad: 0,
        }
    }

    /// Rows of the staged slices 8 halves (16 bytes) longer than their data.
    pub const fn skewed(self) -> Self {
        Self { pad: 8, ..self }
    }

    pub const fn prefetching(self) -> Self {
        Self {
            prefetch: true,
            ..self
        }
    }

    /// The name `NAMED` gives this layout, if any.
    pub fn name(self) -> Option<&'static str> {
        Self::NAMED
            .iter()
            .find(|(_, b)| *b == self)
            .map(|(n, _)| *n)
    }

    pub fn named(name: &str) -> Option<Self> {
        Self::NAMED
            .iter()
            .find(|(n, _)| *n == name)
            .map(|(_, b)| *b)
    }

    /// `COCOG_COOP_BLOCK`'s layout (unset: `SQUARE`); an unknown name is refused with the
    /// names there are.
    pub fn from_env() -> Result<Self, String> {
        match std::env::var("COCOG_COOP_BLOCK") {
            Err(_) => Ok(Self::SQUARE),
            Ok(name) => Self::named(&name).ok_or_else(|| {
                let names: Vec<&str> = Self::NAMED.iter().map(|(n, _)| *n).collect();
                format!(
                    "COCOG_COOP_BLOCK={name}: expected one of {}",
                    names.join(", ")
                )
            }),
        }
    }

    /// Rows, columns and depth of the block in elements, on fragments of side `fr`.
    pub fn dims(self, fr: u32) -> (u32, u32, u32) {
        (
            self.subgroups.0 * self.fragments.0 * fr,
            self.subgroups.1 * self.fragments.1 * fr,
            self.depth * fr,
        )
    }

    /// Invocations of a workgroup and bytes of its workgroup memory, on `f`.
    pub fn footprint(self, f: CoopFragments) -> (u32, u32) {
        let (bm, bn, bk) = self.dims(f.side);
        let subgroups = self.subgroups.0 * self.subgroups.1;
        let bytes =
            2 * (bm * (bk + self.pad) + bk * (bn + self.pad)) + 4 * subgroups * f.side * f.side;
        (subgroups * f.subgroup, bytes)
    }

    /// The accumulators' lines gemm_coop.wgsl leaves to the host: declarations, the products
    /// of one fragment of K, and the stores through `flush`.
    fn lines(self) -> [String; 3] {
        let (wm, wn) = self.fragments;
        let (mut acc, mut products, mut stores) = (String::new(), String::new(), String::new());
        for i in 0..wm {
            products += &format!(
                "            let a{i} = coopLoadT<coop_mat16x16<f16, A>>(&slice_a[(sm + {i}u * FR) * SA + kk], SA);\n"
            );
        }
        for j in 0..wn {
            products += &format!(
                "            let b{j} = coopLoadT<coop_mat16x16<f16, B>>(&slice_b[kk * SB + sn + {j}u * FR], SB);\n"
            );
        }
        for i in 0..wm {
            for j in 0..wn {
                acc += &format!("    var c{i}_{j} = coop_mat16x16<f32, C>();\n");
                products +=
                    &format!("            c{i}_{j} = coopMultiplyAdd(a{i}, b{j}, c{i}_{j});\n");
                // block_c is each subgroup's for one fragment at a time.
                stores += &format!(
                    "    workgroupBarrier();\n    coopStoreT(c{i}_{j}, &block_c[mine], FR);\n    \
                     workgroupBarrier();\n    flush(sub, lane, b, z, m + {i}u * FR, n + {j}u * FR);\n"
                );
            }
        }
        [acc, products, stores]
    }
}

/// Split-K partial products, declared for the problem (no-ops without a split).
fn partials_source(split: bool) -> &'static str {
    if split {
        "@group(0) @binding(1) var<storage, read_write> gemm_partials: array<f32>;\n\
         fn store_partial(s: u32, m: u32, n: u32, v: f32) { gemm_partials[(s * gemm.m + m) * gemm.n + n] = v; }\n\
         fn load_partial(s: u32, m: u32, n: u32) -> f32 { return gemm_partials[(s * gemm.m + m) * gemm.n + n]; }\n"
    } else {
        "fn store_partial(s: u32, m: u32, n: u32, v: f32) {}\n\
         fn load_partial(s: u32, m: u32, n: u32) -> f32 { return 0.0; }\n"
    }
}

impl Gemm {
    /// The tensor-core block layout this product runs in; None where it runs on the f32 tiles
    /// (asked for plainly, or cooperative matrices were not enabled).
    pub fn coop_block(&self) -> Option<CoopBlock> {
        self.cooperative.map(|(_, block)| block)
    }

    /// Compiles gemm.wgsl after `problem`, which defines `load_a`, `load_b` and `epilogue`
    /// and its bindings (2 and up); it may use `gemm.m`, `gemm.n`, `gemm.k` and `gemm.u*`.
    pub fn new(ctx: &GpuContext, label: &str, problem: &str, layout: GemmLayout) -> Self {
        let (_, _, bk) = layout.tile.dims();
        let (ty, tx) = (layout.tile.thread_rows, layout.tile.thread_cols);
        let source = format!(
            "const A_K_FAST: bool = {};\nconst B_K_FAST: bool = {};\nconst SPLIT: bool = {};\n\
             const ONES_COLUMN: bool = {};\n\
             const TY: u32 = {ty}u;\nconst TX: u32 = {tx}u;\nconst BK: u32 = {bk}u;\n{}\n{problem}\n{}",
            layout.a_k_fast,
            layout.b_k_fast,
            layout.split_k,
            layout.ones_column,
            concat!(include_str!("gemm_common.wgsl"), include_str!("gemm.wgsl")),
            partials_source(layout.split_k),
        );
        let module = shader(ctx, label, &source);
        Self {
            layout,
            tile: Kernel::labelled(ctx, &module, "gemm_tile", label),
            reduce: layout.split_k.then(|| {
                Kernel::labelled(ctx, &module, "gemm_reduce", &format!("{label} (reduce)"))
            }),
            cooperative: None,
        }
    }

    /// `new`'s product on cooperative matrices (gemm_coop.wgsl: f16 operands scaled by
    /// `scales`, f32 sums), where the context enabled them (`GpuContext::cooperative`);
    /// `None` elsewhere. `layout.tile` is ignored: blocks are `COCOG_COOP_BLOCK`'s layout
    /// (`CoopBlock::from_env`), or `CoopBlock::SQUARE` where that is unknown or does not fit the
    /// device (said on stderr: the switch is experimental).
    pub fn cooperative(
        ctx: &GpuContext,
        label: &str,
        problem: &str,
        layout: GemmLayout,
        scales: OperandScales,
    ) -> Option<Self> {
        let block = Self::cooperative_block(ctx)?;
        Self::cooperative_with(ctx, label, problem, layout, scales, block)
    }

    /// The layout `cooperative` lays its blocks out in on this context (None without cooperative
    /// matrices): `COCOG_COOP_BLOCK`'s, or `CoopBlock::SQUARE` where that is unknown or does
    /// not fit (said on stderr).
    pub fn cooperative_block(ctx: &GpuContext) -> Option<CoopBlock> {
        let fragments = ctx.cooperative?;
        Some(match CoopBlock::from_env() {
            Ok(b) if Self::fits(ctx, b, fragments) => b,
            // Said once a process: every product of F and the bench's report ask.
            Ok(b) => {
                crate::core::warn_once(
                    "COCOG_COOP_BLOCK",
                    &format!(
                        "COCOG_COOP_BLOCK: {b:?} needs {:?} (invocations, bytes of workgroup memory), more than {} allows; using {:?}",
                        b.footprint(fragments),
                        ctx.adapter_name(),
                        CoopBlock::SQUARE
                    ),
                );
                CoopBlock::SQUARE
            }
            Err(e) => {
                crate::core::warn_once(
                    "COCOG_COOP_BLOCK",
                    &format!("{e}; using {:?}", CoopBlock::SQUARE),
                );
                CoopBlock::SQUARE
            }
        })
    }

    /// Whether `block` on `fragments` fits the device's workgroup limits.
    pub fn fits(ctx: &GpuContext, block: CoopBlock, fragments: CoopFragments) -> bool {
        let limits = ctx.device.limits();
        let (invocations, bytes) = block.footprint(fragments);
        // One-dimensional workgroups: the whole count lies along x.
        invocations <= limits.max_compute_invocations_per_workgroup
            && invocations <= limits.max_compute_workgroup_size_x
            && bytes <= limits.max_compute_workgroup_storage_size
    }

    /// `cooperative` in a given layout; `None` also where it does not fit the device (`fits`).
    pub fn cooperative_with(
        ctx: &GpuContext,
        label: &str,
        problem: &str,
        layout: GemmLayout,
        scales: OperandScales,
        block: CoopBlock,
    ) -> Option<Self> {
        let fragments = ctx.cooperative?;
        // gemm_coop.wgsl multiplies every column; the row sums are gemm.wgsl's alone.
        if layout.ones_column || !Self::fits(ctx, block, fragments) {
            return None;
        }
        let source = Self::cooperative_source(problem, layout, scales, fragments, block);
        let module = shader(ctx, label, &source);
        // The split-K sum is gemm.wgsl's, over the same partials.
        let reduce = layout.split_k.then(|| {
            let plain = Self::new(ctx, label, problem, layout);
            plain.reduce.expect("split-K reduce")
        });
        Some(Self {
            layout,
            tile: Kernel::labelled(ctx, &module, "gemm_tile", &format!("{label} (coop)")),
            reduce,
            cooperative: Some((fragments, block)),
        })
    }

    /// gemm_coop.wgsl after `problem`, enables included (tests compile it without a device).
    pub fn cooperative_source(
        problem: &str,
        layout: GemmLayout,
        scales: OperandScales,
        fragments: CoopFragments,
        block: CoopBlock,
    ) -> String {
        let side = fragments.side;
        let [acc, products, stores] = block.lines();
        let template = concat!(
            include_str!("gemm_common.wgsl"),
            include_str!("gemm_coop.wgsl")
        );
        for marker in [
            "    // ACCUMULATORS\n",
            "            // PRODUCTS\n",
            "    // STORES\n",
        ] {
            assert!(template.contains(marker), "gemm_coop.wgsl lost {marker:?}");
        }
        let body = template
            .replace("    // ACCUMULATORS\n", &acc)
            .replace("            // PRODUCTS\n", &products)
            .replace("    // STORES\n", &stores)
            .replace("coop_mat16x16", &format!("coop_mat{side}x{side}"));
        let (gm, gn) = block.subgroups;
        let (wm, wn) = block.fragments;
        format!(
            "enable f16;\nenable wgpu_cooperative_matrix;\n\
             const A_K_FAST: bool = {};\nconst B_K_FAST: bool = {};\nconst SPLIT: bool = {};\n\
             const ONES_COLUMN: bool = false;\n\
             const SCALE_A: f32 = {:?};\nconst SCALE_B: f32 = {:?};\n\
             const FR: u32 = {side}u;\nconst SG: u32 = {}u;\n\
             const GM: u32 = {gm}u;\nconst GN: u32 = {gn}u;\nconst WM: u32 = {wm}u;\n\
             const WN: u32 = {wn}u;\nconst KF: u32 = {}u;\nconst PREFETCH: bool = {};\n\
             const PAD: u32 = {}u;\n\
             {body}\n{problem}\n{}",
            layout.a_k_fast,
            layout.b_k_fast,
            layout.split_k,
            scales.a,
            scales.b,
            fragments.subgroup,
            block.depth,
            block.prefetch,
            block.pad,
            partials_source(layout.split_k),
        )
    }

    /// Rows, columns and depth of a block of C.
    fn block(&self) -> (u32, u32, u32) {
        match self.cooperative {
            Some((f, block)) => block.dims(f.side),
            None => self.layout.tile.dims(),
        }
    }

    /// Invocations of one workgroup.
    fn invocations(&self) -> u32 {
        match self.cooperative {
            Some((f, block)) => block.footprint(f).0,
            None => self.layout.tile.thread_rows * self.layout.tile.thread_cols,
        }
    }

    /// Parts of K per batch: enough workgroups for about `TARGET_INVOCATIONS`, at least
    /// `MIN_K_SPLIT` of K each, and no more than the partials' binding holds.
    fn parts(&self, shape: &GemmShape, tiles: u32, binding_limit: u64) -> u32 {
        if !self.layout.split_k {
            return 1;
        }
        let by_work = shape.k.div_ceil(MIN_K_SPLIT).max(1);
        let groups = TARGET_INVOCATIONS.div_ceil(self.invocations());
        let by_grid = groups.div_ceil(tiles * shape.batches.max(1)).max(1);
        let slice_bytes =
            u64::from(shape.batches.max(1)) * u64::from(shape.m) * u64::from(shape.n) * 4;
        let by_binding = u32::try_from(binding_limit / slice_bytes.max(1)).unwrap_or(u32::MAX);
        by_work
            .min(by_grid)
            .min(by_binding)
            .min(65_535 / shape.batches.max(1))
            .max(1)
    }

    /// Records C = A·B for `shape`, with the problem's `bindings` (2 and up).
    pub fn encode(
        &self,
        rec: &mut Recorder,
        ws: &mut Workspace,
        shape: GemmShape,
        bindings: &[(u32, &dyn Bind)],
    ) {
        if shape.m == 0 || shape.n == 0 || shape.batches == 0 {
            return;
        }
        let (bm, bn, bk) = self.block();
        let cols = shape.n - u32::from(self.layout.ones_column);
        debug_assert!(cols > 0, "a ones column needs another column beside it");
        let tiles = shape.m.div_ceil(bm) * cols.div_ceil(bn);
        let parts = self.parts(&shape, tiles, rec.ctx().binding_limit());
        let k_split = shape.k.div_ceil(parts).next_multiple_of(bk).max(bk);
        let parts = shape.k.div_ceil(k_split).max(1);
        let dims = rec.uniform(&Dims {
            m: shape.m,
            n: shape.n,
            k: shape.k,
            k_split,
            parts,
            batches: shape.batches,
            params: shape.params,
        });
        let mut all: Vec<(u32, &dyn Bind)> = vec![(0, &dims)];
        all.extend_from_slice(bindings);
        let x = tiles.min(MAX_GRID_X);
        let grid = [x, tiles.div_ceil(x), shape.batches * parts];
        match &self.reduce {
            None => self.tile.dispatch(rec, &all, grid),
            Some(reduce) => {
                let slices = u64::from(shape.batches * parts);
                let bytes = slices * u64::from(shape.m) * u64::from(shape.n) * 4;
                let partials = ws.buffer(rec.ctx(), "gemm partials", bytes);
                all.push((1, &partials));
                self.tile.dispatch(rec, &all, grid);
                // gemm_reduce: 64 values per workgroup, four invocations each.
                reduce.dispatch_1d(rec, &all, (shape.m * shape.n).div_ceil(64));
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::CoopBlock;

    /// `cocog bench` names the layout it ran by `CoopBlock::name`: no two names may share one.
    #[test]
    fn every_named_layout_is_named_back() {
        for (name, block) in CoopBlock::NAMED {
            assert_eq!(block.name(), Some(name), "{block:?}");
        }
    }
}
