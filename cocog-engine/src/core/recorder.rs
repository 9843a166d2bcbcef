//! One submission's worth of GPU work: a command encoder plus the uniform values its
//! dispatches read, packed into pooled uniform buffers and uploaded once at submission.

use std::num::NonZeroU64;
use std::sync::Mutex;

use super::GpuContext;

/// Bytes of one pooled uniform buffer.
const ARENA_BYTES: u64 = 64 * 1024;

/// Uniform buffers waiting to be reused. A queue write to a buffer lands after every earlier
/// submission that reads it, so an arena may be reused as soon as its recorder has submitted.
#[derive(Debug, Default)]
pub(crate) struct ArenaPool(Mutex<Vec<wgpu::Buffer>>);

/// A uniform value's place in an arena; binds like a buffer.
#[derive(Clone, Debug)]
pub struct UniformSlot {
    buffer: wgpu::Buffer,
    offset: u64,
    size: NonZeroU64,
}

/// What a kernel binding can be: a whole buffer or a uniform slot.
pub trait Bind {
    fn binding(&self) -> wgpu::BufferBinding<'_>;
}

impl Bind for wgpu::Buffer {
    fn binding(&self) -> wgpu::BufferBinding<'_> {
        self.as_entire_buffer_binding()
    }
}

/// A range of a buffer (e.g. a band of rows of a frame that is larger than one binding).
impl Bind for wgpu::BufferBinding<'_> {
    fn binding(&self) -> wgpu::BufferBinding<'_> {
        self.clone()
    }
}

impl Bind for super::GpuBuffer {
    fn binding(&self) -> wgpu::BufferBinding<'_> {
        self.buffer.as_entire_buffer_binding()
    }
}

impl Bind for UniformSlot {
    fn binding(&self) -> wgpu::BufferBinding<'_> {
        wgpu::BufferBinding {
            buffer: &self.buffer,
            offset: self.offset,
            size: Some(self.size),
        }
    }
}

/// Records dispatches and copies for one `queue.submit`. Recording the same sequence of
/// dispatches again puts every uniform at the same place in the same arena, so kernels find
/// their bind groups cached. Consecutive dispatches share one compute pass (WebGPU orders the
/// dispatches of a pass as it does separate passes), which spares the host a pass's begin and
/// end per dispatch; a copy or clear through `encoder` ends it.
pub struct Recorder<'c> {
    pub(crate) ctx: &'c GpuContext,
    /// The open compute pass, and whether it is a timed one of a single dispatch. Declared
    /// before the encoder so that it ends before the encoder is dropped.
    pass: Option<(wgpu::ComputePass<'static>, bool)>,
    /// `None` only once submitted.
    encoder: Option<wgpu::CommandEncoder>,
    /// Arenas in use, each with the bytes staged for it.
    arenas: Vec<(wgpu::Buffer, Vec<u8>)>,
}

impl GpuContext {
    /// A fresh recorder; submit it with `Recorder::submit`.
    pub fn recorder(&self) -> Recorder<'_> {
        Recorder {
            ctx: self,
            pass: None,
            encoder: Some(self.device.create_command_encoder(&Default::default())),
            arenas: Vec::new(),
        }
    }

    /// Submits a finished encoder of the caller's own (counted like a recorder's submission).
    pub fn submit(&self, encoder: wgpu::CommandEncoder) -> wgpu::SubmissionIndex {
        let commands = encoder.finish();
        let t = std::time::Instant::now();
        let index = self.queue.submit([commands]);
        self.counters.submission(t.elapsed());
        index
    }

    fn take_arena(&self) -> wgpu::Buffer {
        let pooled = self.arenas.0.lock().ok().and_then(|mut p| p.pop());
        pooled.unwrap_or_else(|| {
            self.counters.buffer_created();
            self.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("uniform arena"),
                size: ARENA_BYTES,
                usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            })
        })
    }
}

impl<'c> Recorder<'c> {
    pub fn ctx(&self) -> &'c GpuContext {
        self.ctx
    }

    /// The encoder, for copies and passes of the caller's own (ends the open compute pass).
    pub fn encoder(&mut self) -> &mut wgpu::CommandEncoder {
        self.pass = None;
        self.encoder
            .as_mut()
            .expect("a recorder is consumed by submit")
    }

    /// The compute pass for the next dispatch: the open one, or, for a dispatch with
    /// `timestamps` (the kernel profiler's), a pass of its own.
    pub(crate) fn compute_pass(
        &mut self,
        label: &str,
        timestamps: Option<wgpu::ComputePassTimestampWrites<'_>>,
    ) -> &mut wgpu::ComputePass<'static> {
        let timed = timestamps.is_some();
        if timed || self.pass.as_ref().is_none_or(|(_, alone)| *alone) {
            self.pass = None;
            let pass = self
                .encoder()
                .begin_compute_pass(&wgpu::ComputePassDescriptor {
                    label: Some(if timed { label } else { "dispatches" }),
                    timestamp_writes: timestamps,
                })
                .forget_lifetime();
            self.pass = Some((pass, timed));
        }
        &mut self.pass.as_mut().expect("a pass was just opened").0
    }

    /// Stages `value` for upload at submission and returns where kernels find it.
    pub fn uniform<T: bytemuck::Pod>(&mut self, value: &T) -> UniformSlot {
        let bytes = bytemuck::bytes_of(value);
        let align = self.ctx.uniform_align;
        let size = (bytes.len() as u64).max(16).next_multiple_of(16);
        let fits =
            |staged: &Vec<u8>| (staged.len() as u64).next_multiple_of(align) + size <= ARENA_BYTES;
        if !self.arenas.last().is_some_and(|(_, s)| fits(s)) {
            let arena = self.ctx.take_arena();
            self.arenas.push((arena, Vec::with_capacity(4096)));
        }
        let (buffer, staged) = self.arenas.last_mut().expect("an arena was just pushed");
        let offset = (staged.len() as u64).next_multiple_of(align);
        staged.resize(offset as usize, 0);
        staged.extend_from_slice(bytes);
        staged.resize((offset + size) as usize, 0);
        UniformSlot {
            buffer: buffer.clone(),
            offset,
            size: NonZeroU64::new(size).expect("size is at least 16"),
        }
    }

    /// Uploads the staged uniforms and submits everything recorded.
    pub fn submit(mut self) -> wgpu::SubmissionIndex {
        let arenas = std::mem::take(&mut self.arenas);
        for (buffer, staged) in &arenas {
            self.ctx.queue.write_buffer(buffer, 0, staged);
        }
        self.pass = None;
        let encoder = self
            .encoder
            .take()
            .expect("a recorder is consumed by submit");
        let index = self.ctx.submit(encoder);
        if let Ok(mut pool) = self.ctx.arenas.0.lock() {
            // Reversed so the next recorder pops them in the order this one used them.
            pool.extend(arenas.into_iter().rev().map(|(b, _)| b));
        }
        index
    }
}

impl Drop for Recorder<'_> {
    fn drop(&mut self) {
        if let Ok(mut pool) = self.ctx.arenas.0.lock() {
            pool.extend(self.arenas.drain(..).rev().map(|(b, _)| b));
        }
    }
}
