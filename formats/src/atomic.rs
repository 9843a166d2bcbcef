//! Whole-file writes that never leave a half-written output behind.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use crate::error::{FormatError, Result};

static COUNTER: AtomicU64 = AtomicU64::new(0);

/// A sibling temp path: the same directory keeps the final rename on one filesystem, so it is atomic.
fn temp_sibling(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "out".to_owned());
    let n = COUNTER.fetch_add(1, Ordering::Relaxed);
    path.with_file_name(format!(".{name}.tmp-{}-{n}", std::process::id()))
}

/// Writes `path` through `fill`, first into a temp file beside it, then renames it into place.
/// On any error the temp file is removed and `path` is left untouched.
pub fn write_atomic<F>(path: &Path, fill: F) -> Result<()>
where
    F: FnOnce(&mut BufWriter<File>) -> Result<()>,
{
    let tmp = temp_sibling(path);
    let outcome = (|| {
        let file = File::create(&tmp).map_err(|e| FormatError::io(path, e))?;
        let mut w = BufWriter::with_capacity(1 << 20, file);
        fill(&mut w)?;
        w.flush().map_err(|e| FormatError::io(path, e))?;
        let file = w
            .into_inner()
            .map_err(|e| FormatError::io(path, e.into_error()))?;
        file.sync_all().map_err(|e| FormatError::io(path, e))?;
        std::fs::rename(&tmp, path).map_err(|e| FormatError::io(path, e))
    })();
    if outcome.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    outcome
}

/// Maps an `io::Error` from a writer to a `FormatError` naming `path`.
pub(crate) fn io_at(path: &Path) -> impl Fn(std::io::Error) -> FormatError + '_ {
    move |e| FormatError::io(path, e)
}
