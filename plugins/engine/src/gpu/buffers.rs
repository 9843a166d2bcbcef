//! Buffer creation with memory accounting, uniform upload and readback.

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

    pub fn reset_peak(&self) {
        self.peak.store(self.live_bytes(), Ordering::Relaxed);
    }
}

/// A storage buffer that un-counts itself from the tracker when dropped.
#[derive(Debug)]
pub struct GpuBuffer {
    pub buffer: wgpu::Buffer,
    tracker: Arc<MemoryTracker>,
}

impl Drop for GpuBuffer {
    fn drop(&mut self) {
        self.tracker
            .live
            .fetch_sub(self.buffer.size(), Ordering::Relaxed);
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
        let buffer = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size,
            usage: STORAGE,
            mapped_at_creation: false,
        });
        self.memory.add(size);
        GpuBuffer {
            buffer,
            tracker: Arc::clone(&self.memory),
        }
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
        let buffer = self
            .device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents: bytes,
                usage: STORAGE,
            });
        self.memory.add(buffer.size());
        GpuBuffer {
            buffer,
            tracker: Arc::clone(&self.memory),
        }
    }

    /// A small uniform buffer; each dispatch gets its own because queued writes to one buffer
    /// would all land before the submission runs.
    pub fn uniform<T: bytemuck::Pod>(&self, value: &T) -> wgpu::Buffer {
        self.device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("params"),
                contents: bytemuck::bytes_of(value),
                usage: wgpu::BufferUsages::UNIFORM,
            })
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
        let staging = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("readback"),
            size: bytes.next_multiple_of(4),
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut encoder = self.device.create_command_encoder(&Default::default());
        encoder.copy_buffer_to_buffer(buffer, offset, &staging, 0, bytes.next_multiple_of(4));
        self.queue.submit([encoder.finish()]);
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
