//! A plugin from the future: its vtable starts with ABI version 999. It deliberately does
//! not depend on cocog-pipeline, as a plugin built against another version would not.
//! Nothing past the version field may be touched by a host that refuses it, so the
//! remaining fields are null.

#[repr(C)]
pub struct FutureVTable {
    abi_version: u32,
    rest: [*const u8; 8],
}

// SAFETY: immutable static data.
unsafe impl Sync for FutureVTable {}

static VTABLE: FutureVTable = FutureVTable {
    abi_version: 999,
    rest: [std::ptr::null(); 8],
};

/// The cocog plugin entry point, with a version no host understands yet.
#[unsafe(no_mangle)]
pub extern "C" fn cocog_plugin_entry() -> *const FutureVTable {
    &VTABLE
}
