//! What every kernel stands on: the device, buffers with memory accounting, recorders that
//! batch a step into one submission, cached dispatch, grow-only workspaces, asynchronous
//! read-back, operation counters, and the headless-Vulkan quieting.

mod buffers;
mod context;
mod counters;
mod headless;
mod kernel;
mod profiler;
mod readback;
mod recorder;
mod switches;
mod workspace;

pub use buffers::{GpuBuffer, MemoryTracker};
pub use context::{CoopFragments, GpuContext, test_gpu};
pub use counters::{CounterSnapshot, Counters};
pub use headless::{device_select_probe_is_futile, quiet_headless_vulkan};
#[cfg(test)]
pub(crate) use kernel::hoist_enables;
pub use kernel::{Kernel, runtime_checks, shader};
pub use profiler::{KernelProfiler, KernelTime};
pub use readback::Readback;
pub use recorder::{Bind, Recorder, UniformSlot};
pub use switches::{env_choice, env_switch, warn_once};
pub use workspace::Workspace;
