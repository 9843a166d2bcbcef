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

/// Where the sorted pairs ended up after an even or odd number of passes.
pub struct Sorted<'a> {
    pub keys: &'a GpuBuffer,
    pub values: &'a GpuBuffer,
}

impl RadixSort {
    pub fn new(ctx: &GpuContext) -> Self {
        let module = shader(ctx, "radix", include_str!("radix.wgsl"));
        Self {
            count: Kernel::new(ctx, &module, "count_digits"),
            scatter: Kernel::new(ctx, &module, "scatter"),
        }
    }

    /// Records a sort of the first `n` pairs on the low `bits` key bits, ping-ponging between
    /// `(keys, values)` and `(keys_tmp, values_tmp)`; returns the pair holding the result.
    pub fn encode<'a>(
        &self,
        ctx: &GpuContext,
        prefix_sum: &PrefixSum,
        encoder: &mut wgpu::CommandEncoder,
        buffers: [&'a GpuBuffer; 4],
        n: u32,
        bits: u32,
    ) -> Sorted<'a> {
        let [mut keys, mut values, mut keys_tmp, mut values_tmp] = buffers;
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
                    &[(0, &params), (1, keys), (2, &histogram)],
                    num_blocks,
                );
                prefix_sum.encode(ctx, encoder, &histogram, num_blocks * 16);
                self.scatter.dispatch_1d(
                    ctx,
                    encoder,
                    &[
                        (0, &params),
                        (1, keys),
                        (2, &histogram),
                        (3, values),
                        (4, keys_tmp),
                        (5, values_tmp),
                    ],
                    num_blocks,
                );
                std::mem::swap(&mut keys, &mut keys_tmp);
                std::mem::swap(&mut values, &mut values_tmp);
            }
        }
        Sorted { keys, values }
    }
}
