//! The one error type of this crate: every variant names the file it is about.

use std::path::{Path, PathBuf};

/// An error reading or writing a file format.
#[derive(Debug, thiserror::Error)]
pub enum FormatError {
    /// The operating system refused a read or write.
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// The file is malformed: `field` names the value that is wrong, `message` what was expected.
    #[error("{path}: {field}: {message}")]
    Invalid {
        path: PathBuf,
        field: String,
        message: String,
    },
    /// The file is well-formed but uses a feature this crate deliberately does not handle.
    #[error("{path}: unsupported: {message}")]
    Unsupported { path: PathBuf, message: String },
}

impl FormatError {
    pub fn io(path: impl AsRef<Path>, source: std::io::Error) -> Self {
        Self::Io {
            path: path.as_ref().to_path_buf(),
            source,
        }
    }

    pub fn invalid(
        path: impl AsRef<Path>,
        field: impl Into<String>,
        message: impl Into<String>,
    ) -> Self {
        Self::Invalid {
            path: path.as_ref().to_path_buf(),
            field: field.into(),
            message: message.into(),
        }
    }

    pub fn unsupported(path: impl AsRef<Path>, message: impl Into<String>) -> Self {
        Self::Unsupported {
            path: path.as_ref().to_path_buf(),
            message: message.into(),
        }
    }

    /// The file this error is about.
    pub fn path(&self) -> &Path {
        match self {
            Self::Io { path, .. } | Self::Invalid { path, .. } | Self::Unsupported { path, .. } => {
                path
            }
        }
    }
}

pub type Result<T, E = FormatError> = std::result::Result<T, E>;

/// Reads a whole file, naming it in the error.
pub fn read_file(path: &Path) -> Result<Vec<u8>> {
    std::fs::read(path).map_err(|e| FormatError::io(path, e))
}

/// Reads a whole UTF-8 file, naming it in the error.
pub fn read_text(path: &Path) -> Result<String> {
    let bytes = read_file(path)?;
    String::from_utf8(bytes).map_err(|e| {
        FormatError::invalid(
            path,
            "encoding",
            format!(
                "expected UTF-8 text, invalid byte at offset {}",
                e.utf8_error().valid_up_to()
            ),
        )
    })
}
