//! Grow-only scratch buffers that outlive a step, so a training loop stops allocating once
//! its sizes have settled.

use std::collections::HashMap;

use super::{GpuBuffer, GpuContext, Recorder};

/// Growth beyond the request, so a Gaussian count that creeps up between densifications does
/// not reallocate every time.
const HEADROOM: f64 = 1.5;

/// Named scratch buffers. A name's buffer is only ever replaced by a larger one; its contents
/// are whatever its last user left unless asked for zeroed.
#[derive(Debug, Default)]
pub struct Workspace {
    buffers: HashMap<&'static str, GpuBuffer>,
}

impl Workspace {
    /// `name`'s buffer, at least `bytes` long.
    pub fn buffer(&mut self, ctx: &GpuContext, name: &'static str, bytes: u64) -> GpuBuffer {
        let bytes = bytes.max(16).next_multiple_of(4);
        match self.buffers.get(name) {
            Some(b) if b.size() >= bytes => b.clone(),
            existing => {
                // A first request is sized exactly: many callers use one size forever. The
                // headroom never takes a buffer that fits one binding past the binding limit
                // (a retried forward would otherwise fail in wgpu for what it planned to fit).
                let size = if existing.is_some() {
                    let grown = ((bytes as f64 * HEADROOM) as u64).next_multiple_of(4);
                    grown.min(ctx.binding_limit().max(bytes))
                } else {
                    bytes
                };
                let b = ctx.storage(name, size);
                self.buffers.insert(name, b.clone());
                b
            }
        }
    }

    /// `name`'s buffer with its first `bytes` cleared to zero by `rec` before what `rec`
    /// records next.
    pub fn zeroed(&mut self, rec: &mut Recorder, name: &'static str, bytes: u64) -> GpuBuffer {
        let b = self.buffer(rec.ctx(), name, bytes);
        let len = bytes.max(16).next_multiple_of(4);
        rec.encoder().clear_buffer(&b, 0, Some(len));
        b
    }
}
