//! GPU stable radix sort of (u32 key, u32 value) pairs.

use super::GpuContext;
use super::buffers::GpuBuffer;
use super::kernel::{Kernel, shader};
use super::scan::PrefixSum;

const BLOCK: u32 = 1024;
const BITS_PER_PASS: u32 = 4;

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    n: u32,
    shift: u32,
    num_blocks: u32,
    pad: u32,
}

#[derive(Debug)]
pub struct RadixSort {
    count: Kernel,
    scatter: Kernel,
}

/// Pairs to sort plus equally sized scratch; after a sort `keys`/`values` hold the result.
#[derive(Debug)]
pub struct SortBuffers {
    pub keys: GpuBuffer,
    pub values: GpuBuffer,
    pub keys_tmp: GpuBuffer,
    pub values_tmp: GpuBuffer,
}

impl SortBuffers {
    /// Scratch for `n` pairs around the given keys and values.
    pub fn new(ctx: &GpuContext, keys: GpuBuffer, values: GpuBuffer, n: u32) -> Self {
        Self {
            keys,
            values,
            keys_tmp: ctx.storage("sort keys tmp", u64::from(n) * 4),
            values_tmp: ctx.storage("sort values tmp", u64::from(n) * 4),
        }
    }
}

impl RadixSort {
    pub fn new(ctx: &GpuContext) -> Self {
        let module = shader(ctx, "radix", include_str!("radix.wgsl"));
        Self {
            count: Kernel::new(ctx, &module, "count_digits"),
            scatter: Kernel::new(ctx, &module, "scatter"),
        }
    }

    /// Records a stable sort of the first `n` pairs on the low `bits` key bits. Passes
    /// ping-pong through the scratch buffers, swapped back so the result is in `keys`/`values`.
    pub fn encode(
        &self,
        ctx: &GpuContext,
        prefix_sum: &PrefixSum,
        encoder: &mut wgpu::CommandEncoder,
        bufs: &mut SortBuffers,
        n: u32,
        bits: u32,
    ) {
        if n > 1 {
            let num_blocks = n.div_ceil(BLOCK);
            let histogram = ctx.storage("radix histogram", u64::from(num_blocks) * 16 * 4);
            for pass in 0..bits.div_ceil(BITS_PER_PASS) {
                let params = ctx.uniform(&Params {
                    n,
                    shift: pass * BITS_PER_PASS,
                    num_blocks,
                    pad: 0,
                });
                self.count.dispatch_1d(
                    ctx,
                    encoder,
                    &[(0, &params), (1, &bufs.keys), (2, &histogram)],
                    num_blocks,
                );
                prefix_sum.encode(ctx, encoder, &histogram, num_blocks * 16);
                self.scatter.dispatch_1d(
                    ctx,
                    encoder,
                    &[
                        (0, &params),
                        (1, &bufs.keys),
                        (2, &histogram),
                        (3, &bufs.values),
                        (4, &bufs.keys_tmp),
                        (5, &bufs.values_tmp),
                    ],
                    num_blocks,
                );
                std::mem::swap(&mut bufs.keys, &mut bufs.keys_tmp);
                std::mem::swap(&mut bufs.values, &mut bufs.values_tmp);
            }
        }
    }
}
