//! GPU exclusive prefix sum over u32 buffers of any length.

use crate::core::GpuContext;
use crate::core::{Kernel, Recorder, Workspace, shader};

const BLOCK: u32 = 1024;
/// Recursion levels of block sums: 1024⁴ elements is beyond any buffer.
const LEVELS: [&str; 4] = ["scan sums 0", "scan sums 1", "scan sums 2", "scan sums 3"];

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    n: u32,
    pad: [u32; 3],
}

#[derive(Debug)]
pub struct PrefixSum {
    scan_blocks: Kernel,
    add_offsets: Kernel,
}

impl PrefixSum {
    pub fn new(ctx: &GpuContext) -> Self {
        let module = shader(ctx, "scan", include_str!("scan.wgsl"));
        Self {
            scan_blocks: Kernel::new(ctx, &module, "scan_blocks"),
            add_offsets: Kernel::new(ctx, &module, "add_block_offsets"),
        }
    }

    /// Records an in-place exclusive scan of the first `n` elements of `data`; block sums live
    /// in `ws`.
    pub fn encode(&self, rec: &mut Recorder, ws: &mut Workspace, data: &wgpu::Buffer, n: u32) {
        self.encode_level(rec, ws, data, n, 0);
    }

    fn encode_level(
        &self,
        rec: &mut Recorder,
        ws: &mut Workspace,
        data: &wgpu::Buffer,
        n: u32,
        level: usize,
    ) {
        if n == 0 {
            return;
        }
        let blocks = n.div_ceil(BLOCK);
        let sums = ws.buffer(
            rec.ctx(),
            LEVELS[level.min(LEVELS.len() - 1)],
            u64::from(blocks) * 4,
        );
        let params = rec.uniform(&Params { n, pad: [0; 3] });
        self.scan_blocks
            .dispatch_1d(rec, &[(0, &params), (1, data), (2, &sums)], blocks);
        if blocks > 1 {
            // The block totals are themselves scanned, then added back to every element.
            self.encode_level(rec, ws, &sums, blocks, level + 1);
            self.add_offsets
                .dispatch_1d(rec, &[(0, &params), (1, data), (2, &sums)], blocks);
        }
    }
}
