//! Compute pipeline creation, bind groups and large-grid dispatch.

use super::GpuContext;

/// Workgroups along x before a 1D grid spills into y (WebGPU's per-dimension limit).
const MAX_GRID_X: u32 = 65_535;

/// One compute entry point; stages with shaders of their own (train's statistics) use it too.
#[derive(Debug)]
pub struct Kernel {
    pipeline: wgpu::ComputePipeline,
    label: &'static str,
}

impl Kernel {
    pub fn new(ctx: &GpuContext, module: &wgpu::ShaderModule, entry: &'static str) -> Self {
        let pipeline = ctx
            .device
            .create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(entry),
                layout: None,
                module,
                entry_point: Some(entry),
                compilation_options: Default::default(),
                cache: None,
            });
        Self {
            pipeline,
            label: entry,
        }
    }

    /// Binds `(binding, buffer)` pairs to group 0 and dispatches `workgroups` (a 1D count that
    /// is folded into a 2D grid when too large; kernels rebuild the linear index).
    pub fn dispatch_1d(
        &self,
        ctx: &GpuContext,
        encoder: &mut wgpu::CommandEncoder,
        bindings: &[(u32, &wgpu::Buffer)],
        workgroups: u32,
    ) {
        if workgroups == 0 {
            return;
        }
        let x = workgroups.min(MAX_GRID_X);
        self.dispatch(ctx, encoder, bindings, [x, workgroups.div_ceil(x), 1]);
    }

    pub fn dispatch(
        &self,
        ctx: &GpuContext,
        encoder: &mut wgpu::CommandEncoder,
        bindings: &[(u32, &wgpu::Buffer)],
        grid: [u32; 3],
    ) {
        if grid.contains(&0) {
            return;
        }
        let entries: Vec<_> = bindings
            .iter()
            .map(|&(binding, buffer)| wgpu::BindGroupEntry {
                binding,
                resource: buffer.as_entire_binding(),
            })
            .collect();
        let bind_group = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some(self.label),
            layout: &self.pipeline.get_bind_group_layout(0),
            entries: &entries,
        });
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some(self.label),
            timestamp_writes: None,
        });
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &bind_group, &[]);
        pass.dispatch_workgroups(grid[0], grid[1], grid[2]);
    }
}

/// Compiles WGSL `source`.
pub fn shader(ctx: &GpuContext, label: &str, source: &str) -> wgpu::ShaderModule {
    ctx.device
        .create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some(label),
            source: wgpu::ShaderSource::Wgsl(source.into()),
        })
}
