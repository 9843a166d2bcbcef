//! Adam for the SH buffer with separate DC and higher-order learning rates; see sh_adam.wgsl.

use cocog_engine::{AdamConfig, AdamMoments, GpuContext};
use wgpu::util::DeviceExt;

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    n: u32,
    coeffs: u32,
    lr_dc: f32,
    lr_rest: f32,
    beta1: f32,
    beta2: f32,
    eps: f32,
    bias1: f32,
    bias2: f32,
    pad: [u32; 3],
}

/// Workgroups along x before the grid spills into y (WebGPU's per-dimension limit).
const MAX_GRID_X: u32 = 65_535;

#[derive(Debug)]
pub(crate) struct ShAdam {
    pipeline: wgpu::ComputePipeline,
}

impl ShAdam {
    pub(crate) fn new(ctx: &GpuContext) -> Self {
        let module = ctx
            .device
            .create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some("sh_adam"),
                source: wgpu::ShaderSource::Wgsl(include_str!("sh_adam.wgsl").into()),
            });
        let pipeline = ctx
            .device
            .create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some("sh_adam"),
                layout: None,
                module: &module,
                entry_point: Some("sh_adam"),
                compilation_options: Default::default(),
                cache: None,
            });
        Self { pipeline }
    }

    /// Records step `t` (1-based): DC coefficients move at `config.lr`, the rest at `lr_rest`.
    pub(crate) fn encode(
        &self,
        ctx: &GpuContext,
        encoder: &mut wgpu::CommandEncoder,
        param: &wgpu::Buffer,
        grad: &wgpu::Buffer,
        moments: &AdamMoments,
        coeffs_per_channel: u32,
        config: &AdamConfig,
        lr_rest: f32,
        t: u32,
    ) {
        if moments.len == 0 {
            return;
        }
        let t = i32::try_from(t.max(1)).unwrap_or(i32::MAX);
        let params = Params {
            n: moments.len,
            coeffs: coeffs_per_channel.max(1),
            lr_dc: config.lr,
            lr_rest,
            beta1: config.beta1,
            beta2: config.beta2,
            eps: config.eps,
            bias1: 1.0 - config.beta1.powi(t),
            bias2: 1.0 - config.beta2.powi(t),
            pad: [0; 3],
        };
        let uniform = ctx
            .device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("sh_adam params"),
                contents: bytemuck::bytes_of(&params),
                usage: wgpu::BufferUsages::UNIFORM,
            });
        let buffers: [&wgpu::Buffer; 5] = [&uniform, param, grad, &moments.m, &moments.v];
        let entries: Vec<_> = buffers
            .iter()
            .enumerate()
            .map(|(i, b)| wgpu::BindGroupEntry {
                binding: i as u32,
                resource: b.as_entire_binding(),
            })
            .collect();
        let bind_group = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("sh_adam"),
            layout: &self.pipeline.get_bind_group_layout(0),
            entries: &entries,
        });
        let groups = moments.len.div_ceil(256);
        let x = groups.min(MAX_GRID_X);
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("sh_adam"),
            timestamp_writes: None,
        });
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &bind_group, &[]);
        pass.dispatch_workgroups(x, groups.div_ceil(x), 1);
    }
}
