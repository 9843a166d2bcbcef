//! GPU exclusive prefix sum over u32 buffers of any length.

use super::GpuContext;
use super::buffers::GpuBuffer;
use super::kernel::{Kernel, shader};

const BLOCK: u32 = 1024;

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

    /// Records an in-place exclusive scan of the first `n` elements of `data`.
    pub fn encode(
        &self,
        ctx: &GpuContext,
        encoder: &mut wgpu::CommandEncoder,
        data: &wgpu::Buffer,
        n: u32,
    ) {
        if n == 0 {
            return;
        }
        let blocks = n.div_ceil(BLOCK);
        let sums: GpuBuffer = ctx.storage("scan block sums", u64::from(blocks) * 4);
        let params = ctx.uniform(&Params { n, pad: [0; 3] });
        self.scan_blocks
            .dispatch_1d(ctx, encoder, &[(0, &params), (1, data), (2, &sums)], blocks);
        if blocks > 1 {
            // The block totals are themselves scanned, then added back to every element.
            self.encode(ctx, encoder, &sums, blocks);
            self.add_offsets.dispatch_1d(
                ctx,
                encoder,
                &[(0, &params), (1, data), (2, &sums)],
                blocks,
            );
        }
    }
}
