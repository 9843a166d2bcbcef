//! The cocog spine.
//!
//! - [`scene`]: the versioned scene directory (`scene.json`) that flows between stages.
//! - [`stage`]: the [`Stage`] trait every stage implements, built in or loaded from a plugin.
//! - [`plugin`]: the C ABI for dynamic plugins, the host-side loader and the guest-side export macro.
//! - [`registry`]: which stage answers to which name, and who provides it.
//! - [`runner`]: runs one stage into a staging path and renames it into place.
//! - [`pipeline`]: runs a `pipeline.toml` chain, checkpointed and resumable.

pub mod atomic;
pub mod context;
pub mod options;
pub mod pipeline;
pub mod plugin;
pub mod registry;
pub mod replace;
pub mod runner;
#[cfg(test)]
mod runner_tests;
pub mod scene;
pub mod stage;
pub mod testing;
mod travel;

pub use context::{Context, LogLevel, NullContext};
pub use options::{OptionKind, OptionSpec, Options, parse_colour};
pub use registry::{Provider, Registry, StageEntry};
pub use scene::{Bounds, Camera, HistoryEntry, Lens, Scene, SceneError, Split, View};
pub use stage::{OutputKind, Stage, StageError, StageInfo, StageKind, StageRequest};

/// The cocog version recorded in scene history.
pub const VERSION: &str = env!("CARGO_PKG_VERSION");
