//! Asynchronous read-back: copies recorded into a step land in a mappable slot, and the CPU
//! collects them a step or more later without waiting for the GPU.

use std::collections::VecDeque;
use std::sync::Arc;
use std::sync::atomic::{AtomicU8, Ordering};

use super::{GpuContext, Recorder};
use crate::EngineError;

const PENDING: u8 = 0;
const MAPPED: u8 = 1;
const FAILED: u8 = 2;
/// Largest size class that is allocated `depth + 1` slots at a time.
const SMALL_CLASS: u64 = 1 << 16;

/// Read sizes rounded up to a power of two (at least 256 bytes), so reads whose size drifts
/// with the scene reuse slots.
fn size_class(bytes: u64) -> u64 {
    bytes.max(256).next_power_of_two()
}

#[derive(Debug)]
struct Slot {
    buffer: wgpu::Buffer,
    state: Arc<AtomicU8>,
}

/// Reads in flight, oldest first; `throttle` keeps their number under `depth`.
#[derive(Debug)]
pub struct Readback<T> {
    depth: usize,
    free: Vec<Slot>,
    /// Recorded but not yet submitted (`start` maps them).
    recorded: Vec<(Slot, u64, T)>,
    in_flight: VecDeque<(Slot, u64, T)>,
}

impl<T> Readback<T> {
    pub fn new(depth: usize) -> Self {
        Self {
            depth: depth.max(1),
            free: Vec::new(),
            recorded: Vec::new(),
            in_flight: VecDeque::new(),
        }
    }

    /// Records copies of `(buffer, offset, bytes)` ranges, concatenated, into a slot tagged
    /// `tag`. Call `start` after submitting `rec`.
    pub fn record(
        &mut self,
        rec: &mut Recorder,
        ranges: &[(&wgpu::Buffer, u64, u64)],
        tag: T,
    ) -> Result<(), EngineError> {
        let ctx = rec.ctx();
        let total: u64 = ranges.iter().map(|r| r.2.next_multiple_of(4)).sum();
        let class = size_class(total);
        // Slots are taken only by reads of their own size class, and a small class gets all
        // the slots it can ever need at once (`depth` in flight plus the one recording): if
        // slots were shared or grown on demand, how many exist would depend on how fast the GPU
        // returned earlier reads, and a warm step could allocate.
        if !self.free.iter().any(|s| s.buffer.size() == class) {
            let count = if class <= SMALL_CLASS {
                self.depth + 1
            } else {
                1
            };
            for _ in 0..count {
                ctx.counters.buffer_created();
                self.free.push(Slot {
                    buffer: ctx.device.create_buffer(&wgpu::BufferDescriptor {
                        label: Some("readback slot"),
                        size: class,
                        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                        mapped_at_creation: false,
                    }),
                    state: Arc::new(AtomicU8::new(PENDING)),
                });
            }
        }
        let i = self
            .free
            .iter()
            .position(|s| s.buffer.size() == class)
            .expect("a slot of this class was just ensured");
        let slot = self.free.swap_remove(i);
        let mut at = 0;
        for &(buffer, offset, bytes) in ranges {
            let len = bytes.next_multiple_of(4);
            rec.encoder()
                .copy_buffer_to_buffer(buffer, offset, &slot.buffer, at, len);
            at += len;
        }
        self.recorded.push((slot, total, tag));
        Ok(())
    }

    /// Maps the slots recorded since the last call; their recorder must have been submitted.
    pub fn start(&mut self) {
        for (slot, total, tag) in self.recorded.drain(..) {
            slot.state.store(PENDING, Ordering::Release);
            let state = Arc::clone(&slot.state);
            slot.buffer
                .slice(..total.max(4))
                .map_async(wgpu::MapMode::Read, move |r| {
                    state.store(if r.is_ok() { MAPPED } else { FAILED }, Ordering::Release);
                });
            self.in_flight.push_back((slot, total, tag));
        }
    }

    /// Waits (counted as a throttle wait) until fewer than `depth` reads are in flight, and
    /// returns what that finished, oldest first. Calling it once a step keeps the CPU at most
    /// `depth` steps ahead of the GPU.
    pub fn throttle(&mut self, ctx: &GpuContext) -> Result<Vec<(T, Vec<u8>)>, EngineError> {
        let mut out = Vec::new();
        while self.in_flight.len() >= self.depth {
            let (slot, _, _) = self.in_flight.front().expect("depth is at least 1");
            let t = std::time::Instant::now();
            wait_mapped(ctx, &slot.state)?;
            ctx.counters.throttle_wait(t.elapsed());
            out.extend(self.take_ready()?);
        }
        Ok(out)
    }

    /// The reads that have finished, oldest first, without waiting for the GPU.
    pub fn collect(&mut self, ctx: &GpuContext) -> Result<Vec<(T, Vec<u8>)>, EngineError> {
        ctx.device
            .poll(wgpu::PollType::Poll)
            .map_err(|e| EngineError::Readback(e.to_string()))?;
        self.take_ready()
    }

    /// Every read in flight, waiting for the GPU (the end of training, a checkpoint).
    pub fn drain(&mut self, ctx: &GpuContext) -> Result<Vec<(T, Vec<u8>)>, EngineError> {
        if let Some((slot, _, _)) = self.in_flight.back() {
            ctx.counters.blocking_read();
            wait_mapped(ctx, &slot.state)?;
        }
        self.take_ready()
    }

    fn take_ready(&mut self) -> Result<Vec<(T, Vec<u8>)>, EngineError> {
        let mut out = Vec::new();
        while let Some((slot, _, _)) = self.in_flight.front() {
            match slot.state.load(Ordering::Acquire) {
                PENDING => break,
                FAILED => {
                    return Err(EngineError::Readback(
                        "mapping a read-back slot failed".into(),
                    ));
                }
                _ => {}
            }
            let (slot, total, tag) = self.in_flight.pop_front().expect("front exists");
            let data = {
                let view = slot
                    .buffer
                    .slice(..total.max(4))
                    .get_mapped_range()
                    .map_err(|e| EngineError::Readback(e.to_string()))?;
                view[..total as usize].to_vec()
            };
            slot.buffer.unmap();
            self.free.push(slot);
            out.push((tag, data));
        }
        Ok(out)
    }
}

fn wait_mapped(ctx: &GpuContext, state: &AtomicU8) -> Result<(), EngineError> {
    while state.load(Ordering::Acquire) == PENDING {
        ctx.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(|e| EngineError::Readback(e.to_string()))?;
    }
    Ok(())
}
