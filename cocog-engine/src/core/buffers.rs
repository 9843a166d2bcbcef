//! Buffer creation with memory accounting, and blocking readback.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use wgpu::util::DeviceExt;

use super::GpuContext;
use crate::EngineError;

/// Bytes of GPU buffers the engine holds now and at most, so benchmarks can report memory.
#[derive(Debug, Default)]
pub struct MemoryTracker {
    live: AtomicU64,
    peak: AtomicU64,
    /// Buffers freed so far: kernels drop cached bind groups when it moves.
    drops: AtomicU64,
}

impl MemoryTracker {
    fn add(&self, bytes: u64) {
        let now = self.live.fetch_add(bytes, Ordering::Relaxed) + bytes;
        self.peak.fetch_max(now, Ordering::Relaxed);
    }

    pub fn live_bytes(&self) -> u64 {
        self.live.load(Ordering::Relaxed)
    }

    pub fn peak_bytes(&self) -> u64 {
        self.peak.load(Ordering::Relaxed)
    }

    pub(crate) fn drops(&self) -> u64 {
        self.drops.load(Ordering::Relaxed)
    }

    pub fn reset_peak(&self) {
        self.peak.store(self.live_bytes(), Ordering::Relaxed);
    }
}

/// A storage buffer counted in the tracker until its last clone is dropped.
#[derive(Clone, Debug)]
pub struct GpuBuffer {
    pub buffer: wgpu::Buffer,
    _owner: Arc<Owner>,
}

/// Un-counts the buffer when the last `GpuBuffer` clone goes.
#[derive(Debug)]
struct Owner {
    size: u64,
    tracker: Arc<MemoryTracker>,
}

impl Drop for Owner {
    fn drop(&mut self) {
        self.tracker.live.fetch_sub(self.size, Ordering::Relaxed);
        self.tracker.drops.fetch_add(1, Ordering::Relaxed);
    }
}

impl GpuBuffer {
    fn tracked(buffer: wgpu::Buffer, tracker: &Arc<MemoryTracker>) -> Self {
        tracker.add(buffer.size());
        Self {
            _owner: Arc::new(Owner {
                size: buffer.size(),
                tracker: Arc::clone(tracker),
            }),
            buffer,
        }
    }
}

impl std::ops::Deref for GpuBuffer {
    type Target = wgpu::Buffer;
    fn deref(&self) -> &wgpu::Buffer {
        &self.buffer
    }
}

const STORAGE: wgpu::BufferUsages = wgpu::BufferUsages::STORAGE
    .union(wgpu::BufferUsages::COPY_SRC)
    .union(wgpu::BufferUsages::COPY_DST);

impl GpuContext {
    /// Zero-initialised storage buffer of `bytes` (at least 16, so empty inputs bind).
    pub fn storage(&self, label: &str, bytes: u64) -> GpuBuffer {
        let size = bytes.max(16).next_multiple_of(4);
        self.counters.buffer_created();
        let buffer = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size,
            usage: STORAGE,
            mapped_at_creation: false,
        });
        GpuBuffer::tracked(buffer, &self.memory)
    }

    /// Storage buffer holding `data` (padded to at least 16 bytes).
    pub fn storage_from<T: bytemuck::Pod>(&self, label: &str, data: &[T]) -> GpuBuffer {
        let bytes: &[u8] = bytemuck::cast_slice(data);
        if bytes.len() < 16 || !bytes.len().is_multiple_of(4) {
            let mut padded = bytes.to_vec();
            padded.resize(bytes.len().max(16).next_multiple_of(4), 0);
            return self.storage_bytes(label, &padded);
        }
        self.storage_bytes(label, bytes)
    }

    fn storage_bytes(&self, label: &str, bytes: &[u8]) -> GpuBuffer {
        self.counters.buffer_created();
        let buffer = self
            .device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents: bytes,
                usage: STORAGE,
            });
        GpuBuffer::tracked(buffer, &self.memory)
    }

    /// Copies the first `len` elements of `buffer` back to the CPU (one GPU→CPU sync).
    pub fn read<T: bytemuck::Pod>(
        &self,
        buffer: &wgpu::Buffer,
        len: usize,
    ) -> Result<Vec<T>, EngineError> {
        self.read_at(buffer, 0, len)
    }

    /// Copies elements `[first, first + len)` of `buffer` back to the CPU.
    pub fn read_at<T: bytemuck::Pod>(
        &self,
        buffer: &wgpu::Buffer,
        first: usize,
        len: usize,
    ) -> Result<Vec<T>, EngineError> {
        let bytes = (len * size_of::<T>()) as u64;
        let offset = (first * size_of::<T>()) as u64;
        if bytes == 0 {
            return Ok(Vec::new());
        }
        self.counters.blocking_read();
        self.counters.buffer_created();
        let staging = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("readback"),
            size: bytes.next_multiple_of(4),
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut encoder = self.device.create_command_encoder(&Default::default());
        encoder.copy_buffer_to_buffer(buffer, offset, &staging, 0, bytes.next_multiple_of(4));
        self.submit(encoder);
        let (tx, rx) = std::sync::mpsc::channel();
        staging.slice(..).map_async(wgpu::MapMode::Read, move |r| {
            let _ = tx.send(r);
        });
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(|e| EngineError::Readback(e.to_string()))?;
        rx.recv()
            .map_err(|e| EngineError::Readback(e.to_string()))?
            .map_err(|e| EngineError::Readback(e.to_string()))?;
        let data = staging
            .slice(..)
            .get_mapped_range()
            .map_err(|e| EngineError::Readback(e.to_string()))?;
        let out = bytemuck::cast_slice::<u8, T>(&data[..len * size_of::<T>()]).to_vec();
        drop(data);
        staging.unmap();
        Ok(out)
    }
}
