//! Compute pipeline creation, cached bind groups and large-grid dispatch.

use std::collections::HashMap;
use std::sync::Mutex;

use super::GpuContext;
use super::recorder::{Bind, Recorder};

/// Workgroups along x before a 1D grid spills into y (WebGPU's per-dimension limit).
const MAX_GRID_X: u32 = 65_535;
/// Bind groups one kernel keeps; a training step binds each kernel a handful of ways.
const CACHE_ENTRIES: usize = 64;

/// (binding, buffer, offset, size): what a bind group entry points at.
type Key = Vec<(u32, wgpu::Buffer, u64, Option<u64>)>;

#[derive(Debug, Default)]
struct Cache {
    /// `MemoryTracker::drops` when the entries were last known to hold no freed buffer.
    generation: u64,
    groups: HashMap<Key, wgpu::BindGroup>,
}

/// One compute entry point; stages with shaders of their own (train's statistics) use it too.
#[derive(Debug)]
pub struct Kernel {
    pipeline: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
    label: String,
    cache: Mutex<Cache>,
}

impl Kernel {
    pub fn new(ctx: &GpuContext, module: &wgpu::ShaderModule, entry: &str) -> Self {
        Self::labelled(ctx, module, entry, entry)
    }

    /// `new` with the name passes, bind groups and the kernel profiler show (several kernels
    /// share an entry point name, e.g. every matrix product's `gemm_tile`).
    pub fn labelled(
        ctx: &GpuContext,
        module: &wgpu::ShaderModule,
        entry: &str,
        label: &str,
    ) -> Self {
        let pipeline = ctx
            .device
            .create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(label),
                layout: None,
                module,
                entry_point: Some(entry),
                compilation_options: Default::default(),
                cache: None,
            });
        Self {
            layout: pipeline.get_bind_group_layout(0),
            pipeline,
            label: label.to_owned(),
            cache: Mutex::default(),
        }
    }

    /// Binds `(binding, buffer)` pairs to group 0 and dispatches `workgroups` (a 1D count that
    /// is folded into a 2D grid when too large; kernels rebuild the linear index).
    pub fn dispatch_1d(&self, rec: &mut Recorder, bindings: &[(u32, &dyn Bind)], workgroups: u32) {
        if workgroups == 0 {
            return;
        }
        let x = workgroups.min(MAX_GRID_X);
        self.dispatch(rec, bindings, [x, workgroups.div_ceil(x), 1]);
    }

    pub fn dispatch(&self, rec: &mut Recorder, bindings: &[(u32, &dyn Bind)], grid: [u32; 3]) {
        if grid.contains(&0) {
            return;
        }
        let ctx = rec.ctx();
        let bind_group = self.bind_group(ctx, bindings);
        ctx.counters.dispatch();
        let timing = ctx.profiler.writes(&self.label);
        let pass = rec.compute_pass(
            &self.label,
            timing
                .as_ref()
                .map(|(set, i)| wgpu::ComputePassTimestampWrites {
                    query_set: set,
                    beginning_of_pass_write_index: Some(*i),
                    end_of_pass_write_index: Some(i + 1),
                }),
        );
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &bind_group, &[]);
        pass.dispatch_workgroups(grid[0], grid[1], grid[2]);
    }

    /// The cached bind group for these bindings, or a new one. The cache is emptied whenever a
    /// buffer was freed since it was filled, so it never keeps dead buffers' memory alive.
    fn bind_group(&self, ctx: &GpuContext, bindings: &[(u32, &dyn Bind)]) -> wgpu::BindGroup {
        let key: Key = bindings
            .iter()
            .map(|(slot, b)| {
                let bb = b.binding();
                (*slot, bb.buffer.clone(), bb.offset, bb.size.map(u64::from))
            })
            .collect();
        let mut cache = self.cache.lock().unwrap_or_else(|e| e.into_inner());
        let generation = ctx.memory.drops();
        if cache.generation != generation || cache.groups.len() >= CACHE_ENTRIES {
            cache.groups.clear();
            cache.generation = generation;
        }
        if let Some(group) = cache.groups.get(&key) {
            return group.clone();
        }
        let entries: Vec<_> = bindings
            .iter()
            .map(|(binding, b)| wgpu::BindGroupEntry {
                binding: *binding,
                resource: wgpu::BindingResource::Buffer(b.binding()),
            })
            .collect();
        ctx.counters.bind_group_created();
        let group = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some(&self.label),
            layout: &self.layout,
            entries: &entries,
        });
        cache.groups.insert(key, group.clone());
        group
    }
}

/// Whether naga guards our kernels at run time (the default): array indices clamped, every
/// loop given an iteration cap, integer divisions guarded against zero. `COCOG_SHADER_CHECKS=0`
/// compiles them without (an experiment until a GPU times it): the kernels are this crate's
/// own, their indices in range and their loops bounded by construction, which the f64-reference
/// tests check with the guards off as well as on. Workgroup memory is still zeroed when a
/// workgroup starts: no test could show that every kernel writes what it reads there. Read once
/// a process.
pub fn runtime_checks() -> bool {
    static CHECKS: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    *CHECKS.get_or_init(|| {
        super::env_choice(
            "COCOG_SHADER_CHECKS",
            &[("0", false), ("1", true)],
            "the checks stay on",
            true,
        )
    })
}

/// Compiles WGSL `source`. Its `enable …;` lines move to the top, where WGSL requires them,
/// so a prelude that needs an extension can be placed anywhere in a composed source.
pub fn shader(ctx: &GpuContext, label: &str, source: &str) -> wgpu::ShaderModule {
    let desc = wgpu::ShaderModuleDescriptor {
        label: Some(label),
        source: wgpu::ShaderSource::Wgsl(hoist_enables(source).into()),
    };
    if runtime_checks() {
        return ctx.device.create_shader_module(desc);
    }
    // SAFETY: the source is one of this crate's kernels: every index stays inside its array
    // and binding, every loop ends and every divisor is non-zero by construction (the
    // kernels' tests run with the checks off too); see `runtime_checks`.
    unsafe {
        ctx.device
            .create_shader_module_trusted(desc, wgpu::ShaderRuntimeChecks::unchecked())
    }
}

pub(crate) fn hoist_enables(source: &str) -> String {
    let is_enable = |l: &&str| l.trim_start().starts_with("enable ");
    let mut out = String::new();
    for line in source.lines().filter(is_enable) {
        let line = format!("{}\n", line.trim());
        if !out.contains(&line) {
            out.push_str(&line);
        }
    }
    for line in source.lines().filter(|l| !is_enable(l)) {
        out.push_str(line);
        out.push('\n');
    }
    out
}

#[cfg(test)]
mod tests {
    #[test]
    fn enable_directives_lead_the_source() {
        let s = super::hoist_enables("const A: u32 = 1u;\n  enable f16;\nfn f() {}\nenable f16;\n");
        assert_eq!(s, "enable f16;\nconst A: u32 = 1u;\nfn f() {}\n");
    }
}
