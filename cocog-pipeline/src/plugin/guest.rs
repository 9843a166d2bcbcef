//! The plugin side of the ABI: what [`export_plugin!`](crate::export_plugin) expands to.
//!
//! Every entry point catches panics: unwinding across `extern "C"` aborts the process,
//! and a plugin bug must become an error for the host, never a crash.

use std::cell::RefCell;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::sync::Once;

use serde::Deserialize;
use serde_json::{Value, json};

use super::abi::{HostCallbacks, OwnedBuf, RunStatus, Slice};
use crate::context::{Context, LogLevel};
use crate::options::Options;
use crate::stage::{Stage, StageError, StageRequest};

/// Exports a plugin. `stages` is a function returning the plugin's stages.
///
/// ```ignore
/// cocog_pipeline::export_plugin!(name: "my-plugin", version: env!("CARGO_PKG_VERSION"), stages: my_stages);
/// ```
#[macro_export]
macro_rules! export_plugin {
    (name: $name:expr, version: $version:expr, stages: $stages:path $(,)?) => {
        /// The cocog plugin entry point.
        #[unsafe(no_mangle)]
        pub extern "C" fn cocog_plugin_entry() -> *const $crate::plugin::abi::PluginVTable {
            unsafe extern "C" fn describe() -> $crate::plugin::abi::OwnedBuf {
                $crate::plugin::guest::describe($name, $version, $stages)
            }
            unsafe extern "C" fn run(
                request: $crate::plugin::abi::Slice,
                host: *const $crate::plugin::abi::HostCallbacks,
                out: *mut $crate::plugin::abi::OwnedBuf,
            ) -> i32 {
                // SAFETY: the host upholds the ABI contract for these pointers.
                unsafe { $crate::plugin::guest::run($stages, request, host, out) }
            }
            static VTABLE: $crate::plugin::abi::PluginVTable = $crate::plugin::abi::PluginVTable {
                abi_version: $crate::plugin::abi::ABI_VERSION,
                describe,
                run,
                free: $crate::plugin::guest::free,
            };
            &VTABLE
        }
    };
}

/// Builds the descriptor JSON. A panic while listing stages becomes `{"error": ...}`.
pub fn describe(name: &str, version: &str, stages: fn() -> Vec<Box<dyn Stage>>) -> OwnedBuf {
    let v = match catch_unwind(|| stages().iter().map(|s| s.info()).collect::<Vec<_>>()) {
        Ok(infos) => json!({ "name": name, "version": version, "stages": infos }),
        Err(p) => {
            json!({ "error": format!("panicked while describing stages: {}", panic_text(&*p)) })
        }
    };
    OwnedBuf::from_vec(v.to_string().into_bytes())
}

#[derive(Deserialize)]
struct WireRequest {
    stage: String,
    input: std::path::PathBuf,
    output: std::path::PathBuf,
    #[serde(default)]
    options: Options,
}

/// Runs one stage for the host.
///
/// # Safety
/// `request` must be valid for reads, `host` must point to live callbacks for the whole
/// call, and `out` must be writable.
pub unsafe fn run(
    stages: fn() -> Vec<Box<dyn Stage>>,
    request: Slice,
    host: *const HostCallbacks,
    out: *mut OwnedBuf,
) -> i32 {
    quiet_panics();
    // SAFETY: guaranteed by the caller.
    let bytes = unsafe { request.as_bytes() };
    // SAFETY: guaranteed by the caller; the host outlives this call.
    let ctx = GuestContext(unsafe { &*host });
    let result = catch_unwind(AssertUnwindSafe(|| -> Result<Value, StageError> {
        let req: WireRequest = serde_json::from_slice(bytes)
            .map_err(|e| StageError::Input(format!("malformed request from host: {e}")))?;
        let all = stages();
        let stage = all
            .iter()
            .find(|s| s.info().name == req.stage)
            .ok_or_else(|| StageError::Input(format!("plugin has no stage '{}'", req.stage)))?;
        let req = StageRequest {
            input: req.input,
            output: req.output,
            options: req.options,
        };
        stage.run(&req, &ctx)
    }));
    let (status, body) = match result {
        Ok(Ok(v)) => (RunStatus::Ok, v),
        Ok(Err(StageError::Cancelled)) => (RunStatus::Cancelled, json!({ "error": "cancelled" })),
        Ok(Err(e)) => (RunStatus::Error, json!({ "error": error_chain(&e) })),
        Err(p) => {
            let located = LAST_PANIC.with(|l| l.borrow_mut().take());
            (
                RunStatus::Panicked,
                json!({ "error": located.unwrap_or_else(|| panic_text(&*p)) }),
            )
        }
    };
    // SAFETY: `out` is writable per the contract.
    unsafe { out.write(OwnedBuf::from_vec(body.to_string().into_bytes())) };
    status as i32
}

/// Releases a buffer this library handed out.
///
/// # Safety
/// `buf` must come from this library and be freed once.
pub unsafe extern "C" fn free(buf: OwnedBuf) {
    // SAFETY: per the contract, the buffer was made by `OwnedBuf::from_vec` here.
    drop(unsafe { buf.into_vec() });
}

thread_local! {
    static LAST_PANIC: RefCell<Option<String>> = const { RefCell::new(None) };
}

/// The plugin has its own copy of std and so its own panic hook. Instead of printing a
/// backtrace into the host's terminal, remember the message and location; the host
/// reports them as a one-line error.
fn quiet_panics() {
    static HOOK: Once = Once::new();
    HOOK.call_once(|| {
        std::panic::set_hook(Box::new(|info| {
            let text = panic_text(info.payload());
            let located = match info.location() {
                Some(l) => format!("{text} (at {}:{})", l.file(), l.line()),
                None => text,
            };
            LAST_PANIC.with(|l| *l.borrow_mut() = Some(located));
        }));
    });
}

fn error_chain(e: &dyn std::error::Error) -> String {
    let mut s = e.to_string();
    let mut src = e.source();
    while let Some(c) = src {
        let t = c.to_string();
        if !s.contains(&t) {
            s.push_str(": ");
            s.push_str(&t);
        }
        src = c.source();
    }
    s
}

fn panic_text(p: &(dyn std::any::Any + Send)) -> String {
    p.downcast_ref::<&str>()
        .map(|s| (*s).to_owned())
        .or_else(|| p.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "unknown panic payload".to_owned())
}

struct GuestContext<'a>(&'a HostCallbacks);

// SAFETY: the host's callbacks forward to its `Context`, which is Send + Sync.
unsafe impl Send for GuestContext<'_> {}
// SAFETY: as above.
unsafe impl Sync for GuestContext<'_> {}

impl Context for GuestContext<'_> {
    fn log(&self, level: LogLevel, message: &str) {
        // SAFETY: the callbacks and `user` are live for the duration of `run`.
        unsafe { (self.0.log)(self.0.user, level as u32, Slice::new(message.as_bytes())) }
    }

    fn progress(&self, task: &str, done: u64, total: u64) {
        // SAFETY: as above.
        unsafe { (self.0.progress)(self.0.user, Slice::new(task.as_bytes()), done, total) }
    }

    fn cancelled(&self) -> bool {
        // SAFETY: as above.
        unsafe { (self.0.cancelled)(self.0.user) != 0 }
    }
}
