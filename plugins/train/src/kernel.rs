//! A compute entry point of this crate's own shaders (the engine keeps its helper private).

use cocog_engine::GpuContext;
use wgpu::util::DeviceExt;

/// Workgroups along x before a 1D grid spills into y (WebGPU's per-dimension limit); the
/// shaders rebuild the linear index from both.
const MAX_GRID_X: u32 = 65_535;

#[derive(Debug)]
pub(crate) struct Kernel {
    pipeline: wgpu::ComputePipeline,
    label: &'static str,
}

impl Kernel {
    pub(crate) fn new(ctx: &GpuContext, source: &str, entry: &'static str) -> Self {
        let module = ctx
            .device
            .create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some(entry),
                source: wgpu::ShaderSource::Wgsl(source.into()),
            });
        let pipeline = ctx
            .device
            .create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(entry),
                layout: None,
                module: &module,
                entry_point: Some(entry),
                compilation_options: Default::default(),
                cache: None,
            });
        Self {
            pipeline,
            label: entry,
        }
    }

    /// Binds `uniform` at 0 and `buffers` at 1.. and runs one thread per element of `n`
    /// (workgroups of 256).
    pub(crate) fn dispatch_1d<T: bytemuck::Pod>(
        &self,
        ctx: &GpuContext,
        encoder: &mut wgpu::CommandEncoder,
        uniform: &T,
        buffers: &[&wgpu::Buffer],
        n: u32,
    ) {
        if n == 0 {
            return;
        }
        let uniform = ctx
            .device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(self.label),
                contents: bytemuck::bytes_of(uniform),
                usage: wgpu::BufferUsages::UNIFORM,
            });
        let mut entries = vec![wgpu::BindGroupEntry {
            binding: 0,
            resource: uniform.as_entire_binding(),
        }];
        entries.extend(
            buffers
                .iter()
                .enumerate()
                .map(|(i, b)| wgpu::BindGroupEntry {
                    binding: i as u32 + 1,
                    resource: b.as_entire_binding(),
                }),
        );
        let bind_group = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some(self.label),
            layout: &self.pipeline.get_bind_group_layout(0),
            entries: &entries,
        });
        let groups = n.div_ceil(256);
        let x = groups.min(MAX_GRID_X);
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some(self.label),
            timestamp_writes: None,
        });
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &bind_group, &[]);
        pass.dispatch_workgroups(x, groups.div_ceil(x), 1);
    }
}
