//! Adapter selection and device creation.

use std::sync::Arc;

use super::buffers::MemoryTracker;
use super::counters::Counters;
use super::profiler::KernelProfiler;
use super::recorder::ArenaPool;
use crate::EngineError;

/// Storage buffers the widest kernel (projection backward) binds at once.
pub(crate) const REQUIRED_STORAGE_BUFFERS: u32 = 12;
/// The rasterizer stages one batch of 256 projected Gaussians (48 B each) in shared memory.
pub(crate) const REQUIRED_WORKGROUP_STORAGE: u32 = 16 * 1024;

/// The f16→f32 cooperative-matrix products `Gemm::cooperative` builds on: `side`×`side`×`side`
/// fragments (16 on NVIDIA's tensor cores, 8 on lavapipe in Mesa 26.2; 25.0 has none), multiplied by
/// subgroups of a fixed `subgroup` width.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CoopFragments {
    pub side: u32,
    pub subgroup: u32,
}

impl CoopFragments {
    /// The largest square f16→f32 shape `offered` of 16 or 8, for adapters whose subgroups
    /// have one width (the kernel lays four subgroups over a workgroup) of 8 to 64. Narrower
    /// ones are refused because lavapipe lists its shapes on 4-wide subgroups (CPUs without
    /// AVX) while its feature bit says no, and wgpu 30 enables the feature from the list and
    /// panics creating the device.
    pub fn choose(
        offered: &[wgpu::CooperativeMatrixProperties],
        subgroup_min: u32,
        subgroup_max: u32,
    ) -> Option<Self> {
        use wgpu::CooperativeScalarType::{F16, F32};
        if subgroup_min != subgroup_max || !(8..=64).contains(&subgroup_min) {
            return None;
        }
        [16, 8].into_iter().find_map(|side| {
            offered
                .iter()
                .any(|c| {
                    (c.m_size, c.n_size, c.k_size, c.ab_type, c.cr_type)
                        == (side, side, side, F16, F32)
                })
                .then_some(Self {
                    side,
                    subgroup: subgroup_min,
                })
        })
    }
}

/// A wgpu device plus what the engine learned about it.
pub struct GpuContext {
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    pub adapter_info: wgpu::AdapterInfo,
    /// Native `atomic<f32>` adds; without them gradients use a compare-exchange loop.
    pub float_atomics: bool,
    /// Subgroup reductions, which cut the backward's atomics by the subgroup width.
    pub subgroups: bool,
    /// WGSL `f16` in storage buffers: F keeps its feature maps in half precision.
    pub shader_f16: bool,
    /// The matrix multiply-add shapes the adapter runs cooperatively (tensor cores), as
    /// `VK_KHR_cooperative_matrix` reports them; wgpu exposes them to WGSL as an experimental
    /// feature. Recorded so benchmarks say what a device could give F's convolutions.
    pub cooperative_matrices: Vec<wgpu::CooperativeMatrixProperties>,
    /// wgpu's experimental cooperative matrices, enabled with these square f16→f32 fragments
    /// (`Gemm::cooperative`). Off unless `COCOG_COOPERATIVE_MATRIX` asks: wgpu marks the
    /// feature as possibly unsound, and no kernel of a training step uses it by default.
    pub cooperative: Option<CoopFragments>,
    pub memory: Arc<MemoryTracker>,
    /// Buffers created, blocking reads, submissions, dispatches: see `Counters`.
    pub counters: Counters,
    /// GPU time per kernel, when enabled (benchmarks).
    pub profiler: KernelProfiler,
    pub(crate) arenas: ArenaPool,
    /// The device's uniform offset alignment, read once (recorders pack every uniform by it).
    pub(crate) uniform_align: u64,
}

impl std::fmt::Debug for GpuContext {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GpuContext")
            .field("adapter", &self.adapter_name())
            .field("float_atomics", &self.float_atomics)
            .field("subgroups", &self.subgroups)
            .field("shader_f16", &self.shader_f16)
            .finish()
    }
}

/// Whether a `COCOG_*` switch is on (a `COCOG_NO_*` one asks for a fallback): set to anything
/// but empty, `0`, `false`, `no` or `off`, so `COCOG_NO_F16=0` reads as people mean it.
fn switched_on(var: &str) -> bool {
    std::env::var(var).is_ok_and(|v| switch_value_on(&v))
}

fn switch_value_on(v: &str) -> bool {
    !matches!(
        v.trim().to_ascii_lowercase().as_str(),
        "" | "0" | "false" | "no" | "off"
    )
}

fn rank(info: &wgpu::AdapterInfo) -> u32 {
    match info.device_type {
        wgpu::DeviceType::DiscreteGpu => 0,
        wgpu::DeviceType::IntegratedGpu => 1,
        wgpu::DeviceType::VirtualGpu => 2,
        wgpu::DeviceType::Other => 3,
        wgpu::DeviceType::Cpu => 4,
    }
}

/// The GPU context GPU tests share, or `None` (reason printed) on a machine without an adapter.
/// With `CI=true` a missing adapter panics instead: CI must never pass by skipping GPU tests.
/// One context per test binary: creating devices is slow on software adapters.
pub fn test_gpu() -> Option<&'static GpuContext> {
    static CTX: std::sync::OnceLock<Option<GpuContext>> = std::sync::OnceLock::new();
    CTX.get_or_init(|| match GpuContext::new() {
        Ok(ctx) => {
            eprintln!("GPU tests run on {}", ctx.adapter_name());
            Some(ctx)
        }
        Err(e) => {
            assert!(
                std::env::var("CI").as_deref() != Ok("true"),
                "CI=true but no usable GPU adapter: {e}"
            );
            eprintln!("skipping GPU test: {e}");
            None
        }
    })
    .as_ref()
}

impl GpuContext {
    /// Picks an adapter: the one whose name contains `COCOG_ADAPTER` if that is set, else the
    /// most capable kind (discrete > integrated > virtual > CPU such as lavapipe).
    pub fn new() -> Result<Self, EngineError> {
        let wanted = std::env::var("COCOG_ADAPTER")
            .ok()
            .filter(|s| !s.is_empty());
        Self::with_adapter(wanted.as_deref())
    }

    /// Like `new`, with an explicit adapter-name substring (case-insensitive).
    pub fn with_adapter(wanted: Option<&str>) -> Result<Self, EngineError> {
        let instance =
            wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
        let mut adapters = pollster::block_on(instance.enumerate_adapters(wgpu::Backends::all()));
        let names = adapters
            .iter()
            .map(|a| {
                let i = a.get_info();
                format!("{} ({:?}, {:?})", i.name, i.backend, i.device_type)
            })
            .collect::<Vec<_>>()
            .join(", ");
        if let Some(w) = wanted {
            let w = w.to_lowercase();
            adapters.retain(|a| a.get_info().name.to_lowercase().contains(&w));
            if adapters.is_empty() {
                return Err(EngineError::AdapterNotFound {
                    wanted: w,
                    available: names,
                });
            }
        }
        adapters.retain(|a| {
            a.get_downlevel_capabilities()
                .flags
                .contains(wgpu::DownlevelFlags::COMPUTE_SHADERS)
        });
        adapters.sort_by_key(|a| rank(&a.get_info()));
        let adapter = adapters.into_iter().next().ok_or_else(|| {
            EngineError::NoAdapter(format!("no compute-capable adapter among [{names}]"))
        })?;
        Self::from_adapter(&adapter)
    }

    fn from_adapter(adapter: &wgpu::Adapter) -> Result<Self, EngineError> {
        let info = adapter.get_info();
        let limits = adapter.limits();
        let missing = |what: &str| EngineError::MissingCapability {
            adapter: info.name.clone(),
            what: what.to_owned(),
        };
        if limits.max_storage_buffers_per_shader_stage < REQUIRED_STORAGE_BUFFERS {
            return Err(missing(&format!(
                "{REQUIRED_STORAGE_BUFFERS} storage buffers per stage"
            )));
        }
        if limits.max_compute_workgroup_storage_size < REQUIRED_WORKGROUP_STORAGE {
            return Err(missing(&format!(
                "{REQUIRED_WORKGROUP_STORAGE} B workgroup storage"
            )));
        }
        if limits.max_compute_invocations_per_workgroup < 256 {
            return Err(missing("256 invocations per workgroup"));
        }
        let float_atomics = adapter
            .features()
            .contains(wgpu::Features::SHADER_FLOAT32_ATOMIC)
            && !switched_on("COCOG_NO_FLOAT_ATOMICS");
        let subgroups = adapter.features().contains(wgpu::Features::SUBGROUP)
            && !switched_on("COCOG_NO_SUBGROUPS");
        let shader_f16 =
            adapter.features().contains(wgpu::Features::SHADER_F16) && !switched_on("COCOG_NO_F16");
        let cooperative_matrices = adapter.cooperative_matrix_properties();
        let cooperative = (switched_on("COCOG_COOPERATIVE_MATRIX")
            && shader_f16
            && adapter
                .features()
                .contains(wgpu::Features::EXPERIMENTAL_COOPERATIVE_MATRIX))
        .then(|| {
            CoopFragments::choose(
                &cooperative_matrices,
                info.subgroup_min_size,
                info.subgroup_max_size,
            )
        })
        .flatten();
        let mut required_features = wgpu::Features::empty();
        if cooperative.is_some() {
            required_features |= wgpu::Features::EXPERIMENTAL_COOPERATIVE_MATRIX;
        }
        if shader_f16 {
            required_features |= wgpu::Features::SHADER_F16;
        }
        if float_atomics {
            required_features |= wgpu::Features::SHADER_FLOAT32_ATOMIC;
        }
        if subgroups {
            required_features |= wgpu::Features::SUBGROUP;
        }
        // Costs nothing until the kernel profiler is enabled.
        required_features |= adapter.features() & wgpu::Features::TIMESTAMP_QUERY;
        // Ask for what the adapter has on buffer sizes: big scenes need big buffers, and
        // asking costs nothing on adapters that have less.
        let required_limits = wgpu::Limits {
            max_storage_buffers_per_shader_stage: limits.max_storage_buffers_per_shader_stage,
            max_storage_buffer_binding_size: limits.max_storage_buffer_binding_size,
            max_buffer_size: limits.max_buffer_size,
            max_compute_workgroup_storage_size: limits.max_compute_workgroup_storage_size,
            ..wgpu::Limits::default()
        };
        let (device, queue) =
            pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
                label: Some("cocog-engine"),
                required_features,
                required_limits,
                // SAFETY: asked for only under COCOG_COOPERATIVE_MATRIX; then wgpu may let
                // a wrong cooperative-matrix shader misbehave, which the kernel's f64 test
                // is there to catch on the device.
                experimental_features: if cooperative.is_some() {
                    unsafe { wgpu::ExperimentalFeatures::enabled() }
                } else {
                    wgpu::ExperimentalFeatures::disabled()
                },
                ..Default::default()
            }))?;
        Ok(Self {
            queue,
            adapter_info: info,
            float_atomics,
            subgroups,
            shader_f16,
            cooperative_matrices,
            cooperative,
            memory: Arc::default(),
            counters: Counters::default(),
            profiler: KernelProfiler::default(),
            arenas: ArenaPool::default(),
            uniform_align: u64::from(device.limits().min_uniform_buffer_offset_alignment),
            device,
        })
    }

    /// Blocks until all submitted GPU work has finished (for timing; the engine itself only
    /// syncs when reading back).
    pub fn wait(&self) -> Result<(), EngineError> {
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map(|_| ())
            .map_err(|e| EngineError::Readback(e.to_string()))
    }

    /// Bytes one storage-buffer binding may span on this device: the smaller of the binding
    /// and buffer limits (lavapipe: 128 MiB).
    pub fn binding_limit(&self) -> u64 {
        let limits = self.device.limits();
        limits
            .max_storage_buffer_binding_size
            .min(limits.max_buffer_size)
    }

    /// The cooperative matrix shapes, e.g. "16×16×16 f16→f32, 16×8×16 f16→f16", or "none".
    pub fn cooperative_matrix_shapes(&self) -> String {
        shapes(&self.cooperative_matrices)
    }

    /// Whether the adapter is a CPU (lavapipe, WARP): the kernels that pay off on a GPU's
    /// many cores and lose on a few CPU threads default by this.
    pub fn is_cpu(&self) -> bool {
        self.adapter_info.device_type == wgpu::DeviceType::Cpu
    }

    /// "name (backend, device type)", for logs and benchmark reports.
    pub fn adapter_name(&self) -> String {
        let i = &self.adapter_info;
        format!("{} ({:?}, {:?})", i.name, i.backend, i.device_type)
    }
}

fn shapes(all: &[wgpu::CooperativeMatrixProperties]) -> String {
    if all.is_empty() {
        return "none".to_owned();
    }
    let name = |t: wgpu::CooperativeScalarType| format!("{t:?}").to_ascii_lowercase();
    all.iter()
        .map(|c| {
            let (m, n, k) = (c.m_size, c.n_size, c.k_size);
            format!("{m}×{n}×{k} {}→{}", name(c.ab_type), name(c.cr_type))
        })
        .collect::<Vec<_>>()
        .join(", ")
}

#[cfg(test)]
mod tests {
    use wgpu::CooperativeScalarType as Scalar;

    fn shape(m: u32, n: u32, k: u32, ab: Scalar, cr: Scalar) -> wgpu::CooperativeMatrixProperties {
        wgpu::CooperativeMatrixProperties {
            m_size: m,
            n_size: n,
            k_size: k,
            ab_type: ab,
            cr_type: cr,
            saturating_accumulation: false,
        }
    }

    #[test]
    fn cooperative_shapes_read_as_m_n_k_and_types() {
        use wgpu::CooperativeScalarType::{F16, F32};
        assert_eq!(super::shapes(&[]), "none");
        assert_eq!(
            super::shapes(&[shape(16, 8, 16, F16, F32), shape(8, 8, 8, F32, F32)]),
            "16×8×16 f16→f32, 8×8×8 f32→f32"
        );
    }

    /// NVIDIA's 16-wide fragments first, lavapipe's 8-wide ones otherwise; only f16→f32, only
    /// square, and only where every subgroup has the one width the kernel lays out.
    #[test]
    fn cooperative_fragments_are_square_f16_to_f32_on_fixed_subgroups() {
        use super::CoopFragments;
        use wgpu::CooperativeScalarType::{F16, F32};
        let nvidia = [
            shape(16, 8, 16, F16, F32),
            shape(16, 16, 16, F16, F16),
            shape(8, 8, 8, F16, F32),
            shape(16, 16, 16, F16, F32),
        ];
        let lavapipe = [shape(8, 8, 8, F16, F16), shape(8, 8, 8, F16, F32)];
        let got = |offered: &[_], lo, hi| CoopFragments::choose(offered, lo, hi);
        let frag = |side, subgroup| Some(CoopFragments { side, subgroup });
        assert_eq!(got(&nvidia, 32, 32), frag(16, 32));
        assert_eq!(got(&lavapipe, 8, 8), frag(8, 8));
        assert_eq!(got(&lavapipe, 4, 8), None);
        assert_eq!(got(&lavapipe, 4, 4), None);
        assert_eq!(got(&lavapipe, 128, 128), None);
        assert_eq!(got(&[shape(16, 16, 16, F16, F16)], 32, 32), None);
        assert_eq!(got(&[shape(16, 8, 16, F16, F32)], 32, 32), None);
        assert_eq!(got(&[], 32, 32), None);
    }

    #[test]
    fn a_switch_is_on_unless_empty_or_false() {
        for v in ["1", "true", "yes", "TRUE", "anything"] {
            assert!(super::switch_value_on(v), "{v}");
        }
        for v in ["", "0", "false", "False", "no", "off", " 0 "] {
            assert!(!super::switch_value_on(v), "{v:?}");
        }
    }
}
