//! Dynamic plugins: a `cdylib` that exports one C function returning a versioned vtable.
//!
//! Only C types cross the boundary; requests, descriptors and results are UTF-8 JSON.
//! A plugin built by another compiler version therefore still loads, and a plugin built
//! for another ABI version is refused by reading one `u32` before anything else.

pub mod abi;
pub mod discover;
mod exports;
pub mod guest;
pub mod host;

pub use abi::{ABI_VERSION, ENTRY_SYMBOL};
pub use discover::{Discovery, discover, plugin_dirs};
pub use host::{LoadedPlugin, PluginError, PluginStage};
