//! The host side of the ABI: load a library, check its version, wrap its stages.

use std::ffi::c_void;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use serde::Deserialize;
use serde_json::{Value, json};

use super::abi::{
    ABI_VERSION, ENTRY_SYMBOL, EntryFn, HostCallbacks, OwnedBuf, PluginVTable, Slice,
};
use crate::context::{Context, LogLevel};
use crate::stage::{Stage, StageError, StageInfo, StageRequest};

#[derive(Debug, thiserror::Error)]
pub enum PluginError {
    #[error("{path}: cannot load as a library: {message}")]
    Load { path: PathBuf, message: String },
    #[error("{path}: {message}")]
    NotALibrary { path: PathBuf, message: String },
    #[error("{path}: not a cocog plugin: it does not export the symbol `{ENTRY_SYMBOL}`")]
    MissingSymbol { path: PathBuf },
    #[error("{path}: `{ENTRY_SYMBOL}` returned a null descriptor")]
    NullDescriptor { path: PathBuf },
    #[error(
        "{path}: plugin built for cocog plugin ABI version {found}, but this cocog ({}) \
         speaks ABI version {ABI_VERSION}; rebuild the plugin against this cocog-pipeline",
        crate::VERSION
    )]
    AbiMismatch { path: PathBuf, found: u32 },
    #[error("{path}: malformed plugin descriptor: {message}")]
    Descriptor { path: PathBuf, message: String },
}

#[derive(Deserialize)]
struct Descriptor {
    name: String,
    version: String,
    stages: Vec<StageInfo>,
}

/// A loaded, version-checked plugin library. It stays loaded while any of its stages live.
pub struct LoadedPlugin {
    pub path: PathBuf,
    pub name: String,
    pub version: String,
    pub stages: Vec<StageInfo>,
    vtable: *const PluginVTable,
    // Declared last so it is dropped (unloaded) after everything that points into it.
    _lib: libloading::Library,
}

// SAFETY: the vtable is immutable static data inside the library, and plugin entry points
// are required to be callable from any thread.
unsafe impl Send for LoadedPlugin {}
// SAFETY: as above.
unsafe impl Sync for LoadedPlugin {}

impl LoadedPlugin {
    /// Loads `path`, checks its ABI version and reads its descriptor. A file that is not a
    /// library ([`PluginError::NotALibrary`]) or lacks the entry point
    /// ([`PluginError::MissingSymbol`]) is never opened.
    pub fn load(path: &Path) -> Result<Arc<Self>, PluginError> {
        let path = path.to_path_buf();
        // Read before opening: dlopen runs the library's constructors, and a library that
        // is not a cocog plugin gets no chance to run anything.
        match super::exports::exports_entry(&path) {
            Ok(true) => {}
            Ok(false) => return Err(PluginError::MissingSymbol { path }),
            Err(message) => return Err(PluginError::NotALibrary { path, message }),
        }
        // SAFETY: loading a library runs its initialisers; that is the trust a user gives
        // a plugin by putting it on the plugin path, and it exports our entry point.
        let lib = unsafe { libloading::Library::new(&path) }.map_err(|e| PluginError::Load {
            path: path.clone(),
            message: loader_message(&e),
        })?;
        // SAFETY: the symbol's type is fixed by the ABI; a library exporting the name
        // with another type violates the contract.
        let entry: EntryFn = unsafe { lib.get::<EntryFn>(ENTRY_SYMBOL.as_bytes()) }
            .map(|s| *s)
            .map_err(|_| PluginError::MissingSymbol { path: path.clone() })?;
        // SAFETY: the entry point takes no arguments and returns a static pointer.
        let vtable = unsafe { entry() };
        if vtable.is_null() {
            return Err(PluginError::NullDescriptor { path });
        }
        // Read the version alone first: the rest of the layout is only known to match
        // when the versions agree.
        // SAFETY: every ABI version starts with a u32 version field.
        let found = unsafe { std::ptr::read(vtable.cast::<u32>()) };
        if found != ABI_VERSION {
            return Err(PluginError::AbiMismatch { path, found });
        }
        // SAFETY: the version matches, so the full vtable layout is ours.
        let vt = unsafe { &*vtable };
        // SAFETY: `describe` takes nothing and returns a buffer freed by `free`.
        let bytes = unsafe { take(vt, (vt.describe)()) };
        let descriptor_error = |message: String| PluginError::Descriptor {
            path: path.clone(),
            message,
        };
        let value: Value =
            serde_json::from_slice(&bytes).map_err(|e| descriptor_error(e.to_string()))?;
        if let Some(err) = value.get("error").and_then(Value::as_str) {
            return Err(descriptor_error(err.to_owned()));
        }
        let d: Descriptor =
            serde_json::from_value(value).map_err(|e| descriptor_error(e.to_string()))?;
        if d.stages.is_empty() {
            return Err(descriptor_error("it declares no stages".to_owned()));
        }
        Ok(Arc::new(Self {
            path,
            name: d.name,
            version: d.version,
            stages: d.stages,
            vtable,
            _lib: lib,
        }))
    }

    /// One [`Stage`] per stage the plugin declares.
    pub fn stage_handles(self: &Arc<Self>) -> Vec<PluginStage> {
        self.stages
            .iter()
            .map(|info| PluginStage {
                plugin: Arc::clone(self),
                info: info.clone(),
            })
            .collect()
    }

    fn vtable(&self) -> &PluginVTable {
        // SAFETY: checked non-null and version-matched in `load`; the library is alive.
        unsafe { &*self.vtable }
    }
}

/// Copies a plugin-owned buffer and hands it back to the plugin's allocator.
///
/// # Safety
/// `buf` must come from this vtable's library.
unsafe fn take(vt: &PluginVTable, buf: OwnedBuf) -> Vec<u8> {
    let copy = if buf.ptr.is_null() {
        Vec::new()
    } else {
        // SAFETY: the plugin guarantees `len` initialised bytes at `ptr`.
        unsafe { std::slice::from_raw_parts(buf.ptr, buf.len) }.to_vec()
    };
    // SAFETY: returned to the allocator that made it.
    unsafe { (vt.free)(buf) };
    copy
}

/// A stage implemented by a plugin library.
pub struct PluginStage {
    plugin: Arc<LoadedPlugin>,
    info: StageInfo,
}

impl PluginStage {
    pub fn plugin(&self) -> &Arc<LoadedPlugin> {
        &self.plugin
    }
}

impl Stage for PluginStage {
    fn info(&self) -> StageInfo {
        self.info.clone()
    }

    fn run(&self, req: &StageRequest, ctx: &dyn Context) -> Result<Value, StageError> {
        let wire = json!({
            "stage": self.info.name,
            "input": req.input,
            "output": req.output,
            "options": req.options,
        })
        .to_string();
        let ctx_ref: &dyn Context = ctx;
        let host = HostCallbacks {
            user: (&raw const ctx_ref).cast::<c_void>(),
            log: host_log,
            progress: host_progress,
            cancelled: host_cancelled,
        };
        let vt = self.plugin.vtable();
        let mut out = OwnedBuf::EMPTY;
        // SAFETY: `wire`, `host` and `out` outlive the call; the vtable is version-checked.
        let status = unsafe { (vt.run)(Slice::new(wire.as_bytes()), &host, &mut out) };
        // SAFETY: `out` was filled by this plugin.
        let bytes = unsafe { take(vt, out) };
        let path = self.plugin.path.display();
        let stage = &self.info.name;
        let value: Value = serde_json::from_slice(&bytes).map_err(|e| {
            StageError::Input(format!(
                "{path}: stage '{stage}' returned malformed JSON: {e}"
            ))
        })?;
        let message = || {
            value
                .get("error")
                .and_then(Value::as_str)
                .unwrap_or("no message")
                .to_owned()
        };
        match status {
            0 => Ok(value),
            1 => Err(StageError::Input(format!("{} [plugin {path}]", message()))),
            2 => Err(StageError::Cancelled),
            3 => Err(StageError::Input(format!(
                "panicked: {} [plugin {path}]",
                message()
            ))),
            s => Err(StageError::Input(format!(
                "unknown status {s} from stage '{stage}': {} [plugin {path}]",
                message()
            ))),
        }
    }
}

/// # Safety
/// `user` is the `&&dyn Context` built in `PluginStage::run`.
unsafe fn user_ctx<'a>(user: *const c_void) -> &'a dyn Context {
    // SAFETY: see above; it lives for the whole `run` call.
    unsafe { *user.cast::<&dyn Context>() }
}

unsafe extern "C" fn host_log(user: *const c_void, level: u32, message: Slice) {
    // SAFETY: pointers come from `PluginStage::run` and the plugin's live buffer.
    let (ctx, msg) = unsafe { (user_ctx(user), message.as_bytes()) };
    let _ = catch_unwind(AssertUnwindSafe(|| {
        ctx.log(LogLevel::from_u32(level), &String::from_utf8_lossy(msg));
    }));
}

unsafe extern "C" fn host_progress(user: *const c_void, task: Slice, done: u64, total: u64) {
    // SAFETY: as in `host_log`.
    let (ctx, task) = unsafe { (user_ctx(user), task.as_bytes()) };
    let _ = catch_unwind(AssertUnwindSafe(|| {
        ctx.progress(&String::from_utf8_lossy(task), done, total);
    }));
}

unsafe extern "C" fn host_cancelled(user: *const c_void) -> u8 {
    // SAFETY: as in `host_log`.
    let ctx = unsafe { user_ctx(user) };
    catch_unwind(AssertUnwindSafe(|| u8::from(ctx.cancelled()))).unwrap_or(1)
}

/// libloading's own text is "dlopen failed"; the loader's reason is its source.
fn loader_message(e: &libloading::Error) -> String {
    match std::error::Error::source(e) {
        Some(cause) => format!("{e}: {cause}"),
        None => e.to_string(),
    }
}
