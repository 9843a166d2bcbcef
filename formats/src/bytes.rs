//! A bounds-checked little-endian cursor whose errors name the file, the field and the offset.

use std::path::Path;

use crate::error::FormatError;

pub(crate) struct ByteReader<'a> {
    path: &'a Path,
    data: &'a [u8],
    pos: usize,
}

macro_rules! read_le {
    ($name:ident, $t:ty) => {
        pub fn $name(&mut self, field: &dyn Fn() -> String) -> Result<$t, FormatError> {
            let b = self.take(std::mem::size_of::<$t>(), field)?;
            Ok(<$t>::from_le_bytes(
                b.try_into().expect("take returned the requested length"),
            ))
        }
    };
}

impl<'a> ByteReader<'a> {
    pub fn new(path: &'a Path, data: &'a [u8]) -> Self {
        Self { path, data, pos: 0 }
    }

    pub fn remaining(&self) -> usize {
        self.data.len() - self.pos
    }

    pub fn take(&mut self, n: usize, field: &dyn Fn() -> String) -> Result<&'a [u8], FormatError> {
        if self.remaining() < n {
            return Err(FormatError::invalid(
                self.path,
                field(),
                format!(
                    "file truncated: needs {n} bytes at offset {}, but the file has {} bytes",
                    self.pos,
                    self.data.len()
                ),
            ));
        }
        let out = &self.data[self.pos..self.pos + n];
        self.pos += n;
        Ok(out)
    }

    read_le!(u8, u8);
    read_le!(u32, u32);
    read_le!(i32, i32);
    read_le!(u64, u64);
    read_le!(f64, f64);

    /// A count that promises `count` records of at least `min_record` bytes each; checked against
    /// the bytes left so a corrupt count fails here instead of allocating gigabytes.
    pub fn count(&mut self, field: &str, min_record: usize) -> Result<usize, FormatError> {
        let at = self.pos;
        let n = self.u64(&|| field.to_owned())?;
        let fits = usize::try_from(n)
            .ok()
            .and_then(|n| n.checked_mul(min_record))
            .is_some_and(|bytes| bytes <= self.remaining());
        if !fits {
            return Err(FormatError::invalid(
                self.path,
                field,
                format!(
                    "count {n} at offset {at} needs at least {min_record} bytes per record, but only {} bytes follow",
                    self.remaining()
                ),
            ));
        }
        Ok(n as usize)
    }

    /// A NUL-terminated UTF-8 string.
    pub fn cstr(&mut self, field: &dyn Fn() -> String) -> Result<String, FormatError> {
        let rest = &self.data[self.pos..];
        let Some(len) = rest.iter().position(|&b| b == 0) else {
            return Err(FormatError::invalid(
                self.path,
                field(),
                format!(
                    "file truncated: string at offset {} has no terminating NUL",
                    self.pos
                ),
            ));
        };
        let s = std::str::from_utf8(&rest[..len]).map_err(|_| {
            FormatError::invalid(
                self.path,
                field(),
                format!("string at offset {} is not UTF-8", self.pos),
            )
        })?;
        self.pos += len + 1;
        Ok(s.to_owned())
    }

    /// Fails unless the whole input was consumed: trailing bytes mean a wrong count upstream.
    pub fn finish(&self, what: &str) -> Result<(), FormatError> {
        if self.remaining() != 0 {
            return Err(FormatError::invalid(
                self.path,
                what,
                format!(
                    "{} unexpected trailing bytes after the last record at offset {} (a count is wrong)",
                    self.remaining(),
                    self.pos
                ),
            ));
        }
        Ok(())
    }
}
