//! Reading a library's export table without loading it: dlopen runs a library's
//! constructors, so only files that export the entry symbol are ever opened.

use std::path::Path;

use object::Object;

use super::abi::ENTRY_SYMBOL;

/// Whether the library at `path` exports [`ENTRY_SYMBOL`], or why it cannot be read as one.
pub fn exports_entry(path: &Path) -> Result<bool, String> {
    let data = std::fs::read(path).map_err(|e| e.to_string())?;
    let file = object::File::parse(&*data).map_err(|e| format!("not a library: {e}"))?;
    // Mach-O prefixes C symbols with an underscore.
    let wanted = |name: &[u8]| {
        name == ENTRY_SYMBOL.as_bytes() || name.strip_prefix(b"_") == Some(ENTRY_SYMBOL.as_bytes())
    };
    let exports = file
        .exports()
        .map_err(|e| format!("cannot read its export table: {e}"))?;
    Ok(exports.iter().any(|e| wanted(e.name())))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn files_that_are_not_libraries_are_not_plugins() {
        let tmp = tempfile::tempdir().unwrap();
        let text = tmp.path().join("libnotes.so");
        std::fs::write(&text, b"not an ELF file").unwrap();
        let why = exports_entry(&text).unwrap_err();
        assert!(why.contains("not a library"), "{why}");
        assert!(exports_entry(&tmp.path().join("absent.so")).is_err());
    }

    #[test]
    fn this_test_binary_does_not_export_the_entry() {
        // The test executable is an object file of this platform without the symbol.
        let me = std::env::current_exe().unwrap();
        assert_eq!(exports_entry(&me), Ok(false));
    }
}
