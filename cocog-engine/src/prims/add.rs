//! `total += part` over f32 buffers (add.wgsl): gradients summed from pieces computed apart.

use crate::core::{Bind, GpuContext, Kernel, Recorder, shader};

#[derive(Debug)]
pub struct AddInto {
    kernel: Kernel,
}

impl AddInto {
    pub fn new(ctx: &GpuContext) -> Self {
        let module = shader(ctx, "add", include_str!("add.wgsl"));
        Self {
            kernel: Kernel::new(ctx, &module, "add_into"),
        }
    }

    /// Records `total[i] += part[i]` for the first `count` floats.
    pub fn encode(&self, rec: &mut Recorder, part: &dyn Bind, total: &dyn Bind, count: u32) {
        let u = rec.uniform(&[count, 0, 0, 0]);
        self.kernel
            .dispatch_1d(rec, &[(0, &u), (1, part), (2, total)], count.div_ceil(256));
    }
}
