//! The C ABI shared by host and plugins. Changing any type here means bumping
//! [`ABI_VERSION`].
//!
//! Protocol:
//! 1. The host resolves [`ENTRY_SYMBOL`] (`cocog_plugin_entry`) and calls it. It returns a
//!    pointer to a static [`PluginVTable`] whose first field is the ABI version; the host
//!    reads that field alone and refuses the library unless it equals [`ABI_VERSION`].
//! 2. `describe` returns the descriptor JSON:
//!    `{"name", "version", "stages": [StageInfo, ...]}`.
//! 3. `run` takes the request JSON `{"stage", "input", "output", "options"}` and host
//!    callbacks; it fills `out` with the result JSON and returns a [`RunStatus`] code. On
//!    error, `out` holds `{"error": "message"}`.
//! 4. Every buffer the plugin hands out is released with the plugin's own `free`.

use std::ffi::c_void;

pub const ABI_VERSION: u32 = 1;
pub const ENTRY_SYMBOL: &str = "cocog_plugin_entry";

/// Borrowed bytes: valid only for the duration of the call.
#[repr(C)]
#[derive(Clone, Copy)]
pub struct Slice {
    pub ptr: *const u8,
    pub len: usize,
}

impl Slice {
    pub fn new(bytes: &[u8]) -> Self {
        Self {
            ptr: bytes.as_ptr(),
            len: bytes.len(),
        }
    }

    /// # Safety
    /// `ptr` must point to `len` readable bytes for the returned lifetime (or be null).
    pub unsafe fn as_bytes<'a>(self) -> &'a [u8] {
        if self.ptr.is_null() || self.len == 0 {
            &[]
        } else {
            // SAFETY: the caller guarantees `ptr` points to `len` live bytes.
            unsafe { std::slice::from_raw_parts(self.ptr, self.len) }
        }
    }
}

/// Bytes owned by the plugin's allocator; give them back with `PluginVTable::free`.
#[repr(C)]
pub struct OwnedBuf {
    pub ptr: *mut u8,
    pub len: usize,
    pub cap: usize,
}

impl OwnedBuf {
    pub const EMPTY: Self = Self {
        ptr: std::ptr::null_mut(),
        len: 0,
        cap: 0,
    };

    pub fn from_vec(v: Vec<u8>) -> Self {
        let mut v = std::mem::ManuallyDrop::new(v);
        Self {
            ptr: v.as_mut_ptr(),
            len: v.len(),
            cap: v.capacity(),
        }
    }

    /// # Safety
    /// Must be called in the library that created the buffer, at most once.
    pub unsafe fn into_vec(self) -> Vec<u8> {
        if self.ptr.is_null() {
            Vec::new()
        } else {
            // SAFETY: the buffer came from `from_vec` in this same allocator.
            unsafe { Vec::from_raw_parts(self.ptr, self.len, self.cap) }
        }
    }
}

/// Codes returned by `run`.
#[repr(i32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RunStatus {
    Ok = 0,
    Error = 1,
    Cancelled = 2,
    Panicked = 3,
}

/// Callbacks the host passes to `run`. `user` is opaque to the plugin.
#[repr(C)]
pub struct HostCallbacks {
    pub user: *const c_void,
    pub log: unsafe extern "C" fn(user: *const c_void, level: u32, message: Slice),
    pub progress: unsafe extern "C" fn(user: *const c_void, task: Slice, done: u64, total: u64),
    pub cancelled: unsafe extern "C" fn(user: *const c_void) -> u8,
}

/// Only the first field is read before the version check.
#[repr(C)]
pub struct PluginVTable {
    pub abi_version: u32,
    pub describe: unsafe extern "C" fn() -> OwnedBuf,
    pub run:
        unsafe extern "C" fn(request: Slice, host: *const HostCallbacks, out: *mut OwnedBuf) -> i32,
    pub free: unsafe extern "C" fn(buf: OwnedBuf),
}

/// The signature of [`ENTRY_SYMBOL`].
pub type EntryFn = unsafe extern "C" fn() -> *const PluginVTable;
