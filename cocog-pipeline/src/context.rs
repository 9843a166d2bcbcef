//! What a running stage can tell the host, and how it learns it should stop.

use crate::stage::StageError;

#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
#[repr(u32)]
pub enum LogLevel {
    Error = 0,
    Warn = 1,
    Info = 2,
    Debug = 3,
}

impl LogLevel {
    pub fn from_u32(v: u32) -> Self {
        match v {
            0 => Self::Error,
            1 => Self::Warn,
            2 => Self::Info,
            _ => Self::Debug,
        }
    }

    pub fn as_str(self) -> &'static str {
        match self {
            Self::Error => "error",
            Self::Warn => "warn",
            Self::Info => "info",
            Self::Debug => "debug",
        }
    }
}

/// The host side of a running stage: logs, progress and cancellation.
///
/// Progress is keyed by a task name so a stage can report several phases
/// (e.g. "load images", then "train"); `total == 0` means unknown length.
pub trait Context: Send + Sync {
    fn log(&self, level: LogLevel, message: &str);
    fn progress(&self, task: &str, done: u64, total: u64);
    fn cancelled(&self) -> bool;
}

impl dyn Context + '_ {
    pub fn info(&self, message: &str) {
        self.log(LogLevel::Info, message);
    }

    pub fn warn(&self, message: &str) {
        self.log(LogLevel::Warn, message);
    }

    pub fn debug(&self, message: &str) {
        self.log(LogLevel::Debug, message);
    }

    /// Long loops call this between units of work so Ctrl-C stops them promptly.
    pub fn check_cancelled(&self) -> Result<(), StageError> {
        if self.cancelled() {
            Err(StageError::Cancelled)
        } else {
            Ok(())
        }
    }
}

/// A context that drops logs and progress and is never cancelled: for tests and library use.
#[derive(Default)]
pub struct NullContext;

impl Context for NullContext {
    fn log(&self, _level: LogLevel, _message: &str) {}
    fn progress(&self, _task: &str, _done: u64, _total: u64) {}
    fn cancelled(&self) -> bool {
        false
    }
}
