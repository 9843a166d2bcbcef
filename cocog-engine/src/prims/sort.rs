//! GPU stable radix sort of (u32 key, u32 value) pairs.

use super::PrefixSum;
use crate::core::{GpuBuffer, GpuContext};
use crate::core::{Kernel, Recorder, Workspace, shader};

const BLOCK: u32 = 1024;
const BITS_PER_PASS: u32 = 8;
const DIGITS: u32 = 1 << BITS_PER_PASS;
/// `Params::count_at` when the host knows the count.
const HOST_COUNT: u32 = u32::MAX;

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    n: u32,
    shift: u32,
    num_blocks: u32,
    count_at: u32,
    mask: u32,
    drop: u32,
    pad: [u32; 2],
}

#[derive(Debug)]
pub struct RadixSort {
    count: Kernel,
    scatter: Kernel,
}

/// Pairs to sort plus equally sized scratch; after a sort `keys`/`values` hold the result.
#[derive(Clone, Debug)]
pub struct SortBuffers {
    pub keys: GpuBuffer,
    pub values: GpuBuffer,
    pub keys_tmp: GpuBuffer,
    pub values_tmp: GpuBuffer,
}

impl SortBuffers {
    /// Fresh scratch for `n` pairs around the given keys and values.
    pub fn new(ctx: &GpuContext, keys: GpuBuffer, values: GpuBuffer, n: u32) -> Self {
        Self {
            keys,
            values,
            keys_tmp: ctx.storage("sort keys tmp", u64::from(n) * 4),
            values_tmp: ctx.storage("sort values tmp", u64::from(n) * 4),
        }
    }
}

/// How many pairs to sort: known to the host, or at most `capacity` with the true count at
/// element `index` of a GPU buffer (pairs past the count are left alone).
#[derive(Clone, Copy, Debug)]
pub enum SortCount<'a> {
    Host(u32),
    Gpu {
        capacity: u32,
        buffer: &'a wgpu::Buffer,
        index: u32,
    },
}

impl RadixSort {
    /// A sort whose kernels profile under their own names, e.g. "scatter (depth)", so a
    /// profile tells one sort of a pass from another.
    pub fn new(ctx: &GpuContext, what: &str) -> Self {
        let module = shader(ctx, "radix", include_str!("radix.wgsl"));
        let kernel =
            |entry: &str| Kernel::labelled(ctx, &module, entry, &format!("{entry} ({what})"));
        Self {
            count: kernel("count_digits"),
            scatter: kernel("scatter"),
        }
    }

    /// Records a stable sort of the pairs on the low `bits` key bits. Passes ping-pong through
    /// the scratch buffers; `bufs` ends up naming whichever pair holds the result.
    ///
    /// With `kept`, the pairs whose key is `u32::MAX` are dropped: the sorted pairs are the
    /// first `kept[0]` of `bufs` (written on the GPU; past them the buffers hold scratch). The
    /// first pass sorts every pair and sets the dropped ones aside, the later passes only the
    /// kept ones — a depth sort where most Gaussians are culled costs about one full pass.
    #[allow(clippy::too_many_arguments)]
    pub fn encode(
        &self,
        rec: &mut Recorder,
        ws: &mut Workspace,
        prefix_sum: &PrefixSum,
        bufs: &mut SortBuffers,
        count: SortCount,
        bits: u32,
        kept: Option<&GpuBuffer>,
    ) {
        // The kernels never read these then, but bindings 6 and 7 must hold other buffers
        // (binding 7 is written, so never the buffer binding 6 reads).
        let unused = |rec: &Recorder, ws: &mut Workspace, label| ws.buffer(rec.ctx(), label, 16);
        let (n, mut count_buf, mut count_at) = match count {
            SortCount::Host(n) => (n, unused(rec, ws, "radix no count").buffer, HOST_COUNT),
            SortCount::Gpu {
                capacity,
                buffer,
                index,
            } => (capacity, buffer.clone(), index),
        };
        if n <= 1 && count_at == HOST_COUNT && kept.is_none() {
            return;
        }
        let no_kept = unused(rec, ws, "radix no kept count");
        let num_blocks = n.div_ceil(BLOCK).max(1);
        // A dropping pass has one more row, after every digit's.
        let rows = DIGITS + u32::from(kept.is_some());
        let histogram = ws.buffer(
            rec.ctx(),
            "radix histogram",
            u64::from(num_blocks) * u64::from(rows) * 4,
        );
        for pass in 0..bits.div_ceil(BITS_PER_PASS) {
            let shift = pass * BITS_PER_PASS;
            // The last pass's digit holds only the bits left to sort: keys may carry others.
            let width = (bits - shift).min(BITS_PER_PASS);
            let drop = pass == 0 && kept.is_some();
            let params = rec.uniform(&Params {
                n,
                shift,
                num_blocks,
                count_at,
                mask: (1 << width) - 1,
                drop: u32::from(drop),
                pad: [0; 2],
            });
            let kept_out = match kept {
                Some(k) if drop => k,
                _ => &no_kept,
            };
            self.count.dispatch_1d(
                rec,
                &[
                    (0, &params),
                    (1, &bufs.keys),
                    (2, &histogram),
                    (6, &count_buf),
                ],
                num_blocks,
            );
            let rows = if drop { DIGITS + 1 } else { DIGITS };
            prefix_sum.encode(rec, ws, &histogram, num_blocks * rows);
            self.scatter.dispatch_1d(
                rec,
                &[
                    (0, &params),
                    (1, &bufs.keys),
                    (2, &histogram),
                    (3, &bufs.values),
                    (4, &bufs.keys_tmp),
                    (5, &bufs.values_tmp),
                    (6, &count_buf),
                    (7, kept_out),
                ],
                num_blocks,
            );
            std::mem::swap(&mut bufs.keys, &mut bufs.keys_tmp);
            std::mem::swap(&mut bufs.values, &mut bufs.values_tmp);
            if let (Some(k), true) = (kept, drop) {
                // The later passes sort only what the first kept.
                count_buf = k.buffer.clone();
                count_at = 0;
            }
        }
    }
}
