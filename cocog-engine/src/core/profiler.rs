//! GPU time per kernel, from timestamp queries written at the start and end of every compute
//! pass while enabled (adapters with `TIMESTAMP_QUERY` only). For benchmarks: collecting waits
//! for the GPU.

use std::collections::BTreeMap;
use std::sync::Mutex;

use super::GpuContext;
use crate::EngineError;

/// Passes timed between two collections (wgpu allows 4096 queries a set); later ones go
/// untimed.
const CAPACITY: u32 = 2048;

#[derive(Debug, Default)]
struct State {
    enabled: bool,
    queries: Option<(wgpu::QuerySet, wgpu::Buffer, wgpu::Buffer)>,
    /// The kernel behind each pair of queries written since the last collection.
    pending: Vec<String>,
    /// Per kernel: passes and nanoseconds.
    totals: BTreeMap<String, (u64, f64)>,
}

/// Per-kernel GPU time; see `GpuContext::profiler`.
#[derive(Debug, Default)]
pub struct KernelProfiler {
    state: Mutex<State>,
}

/// One kernel's share of the time collected.
#[derive(Clone, Debug, PartialEq)]
pub struct KernelTime {
    pub kernel: String,
    pub passes: u64,
    pub ms: f64,
}

impl KernelProfiler {
    fn lock(&self) -> std::sync::MutexGuard<'_, State> {
        self.state.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Starts timing passes; false when the device cannot write timestamps.
    pub fn enable(&self, ctx: &GpuContext) -> bool {
        if !ctx
            .device
            .features()
            .contains(wgpu::Features::TIMESTAMP_QUERY)
        {
            return false;
        }
        let mut s = self.lock();
        if s.queries.is_none() {
            let bytes = u64::from(2 * CAPACITY) * 8;
            let set = ctx.device.create_query_set(&wgpu::QuerySetDescriptor {
                label: Some("kernel timestamps"),
                ty: wgpu::QueryType::Timestamp,
                count: 2 * CAPACITY,
            });
            let resolve = ctx.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("timestamp resolve"),
                size: bytes,
                usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            });
            let staging = ctx.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("timestamp staging"),
                size: bytes,
                usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            s.queries = Some((set, resolve, staging));
        }
        s.enabled = true;
        true
    }

    /// Where the pass of `kernel` writes its two timestamps, when timing.
    pub(crate) fn writes(&self, kernel: &str) -> Option<(wgpu::QuerySet, u32)> {
        let mut s = self.lock();
        if !s.enabled || s.pending.len() as u32 >= CAPACITY {
            return None;
        }
        let set = s.queries.as_ref()?.0.clone();
        let index = 2 * s.pending.len() as u32;
        s.pending.push(kernel.to_owned());
        Some((set, index))
    }

    /// Waits for the GPU and adds the passes timed since the last collection to the totals.
    pub fn collect(&self, ctx: &GpuContext) -> Result<(), EngineError> {
        let mut s = self.lock();
        let count = 2 * s.pending.len() as u32;
        let Some((set, resolve, staging)) = s.queries.clone() else {
            return Ok(());
        };
        if count == 0 {
            return Ok(());
        }
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        encoder.resolve_query_set(&set, 0..count, &resolve, 0);
        encoder.copy_buffer_to_buffer(&resolve, 0, &staging, 0, u64::from(count) * 8);
        ctx.submit(encoder);
        let stamps = map_u64(ctx, &staging, count as usize)?;
        let period = f64::from(ctx.queue.get_timestamp_period());
        let pending = std::mem::take(&mut s.pending);
        for (i, kernel) in pending.into_iter().enumerate() {
            let ns = stamps[2 * i + 1].saturating_sub(stamps[2 * i]) as f64 * period;
            let e = s.totals.entry(kernel).or_default();
            e.0 += 1;
            e.1 += ns;
        }
        Ok(())
    }

    /// Totals since the last `take`, largest first; clears them.
    pub fn take(&self) -> Vec<KernelTime> {
        let mut s = self.lock();
        let mut out: Vec<KernelTime> = std::mem::take(&mut s.totals)
            .into_iter()
            .map(|(kernel, (passes, ns))| KernelTime {
                kernel,
                passes,
                ms: ns * 1e-6,
            })
            .collect();
        out.sort_by(|a, b| b.ms.total_cmp(&a.ms));
        out
    }

    pub fn disable(&self) {
        self.lock().enabled = false;
    }
}

fn map_u64(ctx: &GpuContext, buffer: &wgpu::Buffer, len: usize) -> Result<Vec<u64>, EngineError> {
    let slice = buffer.slice(..(len as u64 * 8));
    let (tx, rx) = std::sync::mpsc::channel();
    slice.map_async(wgpu::MapMode::Read, move |r| {
        let _ = tx.send(r);
    });
    ctx.wait()?;
    rx.recv()
        .map_err(|e| EngineError::Readback(e.to_string()))?
        .map_err(|e| EngineError::Readback(e.to_string()))?;
    let view = slice
        .get_mapped_range()
        .map_err(|e| EngineError::Readback(e.to_string()))?;
    let out = bytemuck::pod_collect_to_vec(&view[..]);
    drop(view);
    buffer.unmap();
    Ok(out)
}
