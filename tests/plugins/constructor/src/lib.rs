//! Not a cocog plugin: it exports no entry point, but its constructor runs the moment the
//! library is loaded and writes the file named by `COCOG_TEST_CONSTRUCTOR_MARK`. Plugin
//! discovery must leave that file unwritten.

/// Runs at load time on Linux; on other systems the fixture is inert.
extern "C" fn leave_mark() {
    if let Some(path) = std::env::var_os("COCOG_TEST_CONSTRUCTOR_MARK") {
        let _ = std::fs::write(path, b"constructor ran");
    }
}

#[cfg(target_os = "linux")]
#[used]
#[unsafe(link_section = ".init_array")]
static LEAVE_MARK: extern "C" fn() = leave_mark;

/// Something to export, so the library is an ordinary shared object with a symbol table.
#[unsafe(no_mangle)]
pub extern "C" fn cocog_test_constructor_answer() -> u32 {
    42
}
