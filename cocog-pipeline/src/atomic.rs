//! All-or-nothing outputs: write beside the target, then rename into place.
//!
//! A rename within one directory is atomic on every filesystem we care about, so a reader
//! (or a crashed run) never sees a half-written file or scene directory.

use std::fs;
use std::io::{self, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

static COUNTER: AtomicU64 = AtomicU64::new(0);

/// A unique hidden sibling of `target` in the same directory.
pub fn sibling_temp(target: &Path) -> PathBuf {
    let n = COUNTER.fetch_add(1, Ordering::Relaxed);
    let name = target
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "output".to_owned());
    let parent = target.parent().unwrap_or_else(|| Path::new(""));
    parent.join(format!(".{name}.cocog-tmp-{}-{n}", std::process::id()))
}

/// Writes `bytes` to `path` atomically.
pub fn write(path: &Path, bytes: &[u8]) -> io::Result<()> {
    write_with(path, |f| f.write_all(bytes))
}

/// Creates `path` atomically through a writer callback; on error nothing is left behind.
pub fn write_with(
    path: &Path,
    fill: impl FnOnce(&mut io::BufWriter<fs::File>) -> io::Result<()>,
) -> io::Result<()> {
    let tmp = sibling_temp(path);
    let result = (|| {
        let mut w = io::BufWriter::new(fs::File::create(&tmp)?);
        fill(&mut w)?;
        let f = w.into_inner().map_err(|e| e.into_error())?;
        f.sync_all()?;
        fs::rename(&tmp, path)
    })();
    if result.is_err() {
        let _ = fs::remove_file(&tmp);
    }
    result
}

/// A staging file or directory that is removed on drop unless committed.
pub struct Staging {
    path: PathBuf,
    committed: bool,
}

impl Staging {
    /// Reserves a staging path next to `target` (the path itself is not created).
    pub fn beside(target: &Path) -> Self {
        Self {
            path: sibling_temp(target),
            committed: false,
        }
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Moves the staged output to `target`, replacing an existing one only if `force`.
    pub fn commit(mut self, target: &Path, force: bool) -> io::Result<()> {
        if !self.path.exists() {
            return Err(io::Error::new(
                io::ErrorKind::NotFound,
                "the stage finished but wrote no output",
            ));
        }
        if target.exists() || target.is_symlink() {
            if !force {
                return Err(io::Error::new(
                    io::ErrorKind::AlreadyExists,
                    "output already exists (use --force to replace it)",
                ));
            }
            remove_any(target)?;
        }
        fs::rename(&self.path, target)?;
        self.committed = true;
        Ok(())
    }
}

impl Drop for Staging {
    fn drop(&mut self) {
        if !self.committed && (self.path.exists() || self.path.is_symlink()) {
            let _ = remove_any(&self.path);
        }
    }
}

fn remove_any(p: &Path) -> io::Result<()> {
    if p.is_dir() && !p.is_symlink() {
        fs::remove_dir_all(p)
    } else {
        fs::remove_file(p)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn failed_write_leaves_nothing() {
        let dir = tempfile::tempdir().expect("tempdir");
        let target = dir.path().join("a.txt");
        let r = write_with(&target, |w| {
            w.write_all(b"partial")?;
            Err(io::Error::other("boom"))
        });
        assert!(r.is_err());
        let left: Vec<_> = fs::read_dir(dir.path()).expect("read_dir").collect();
        assert!(left.is_empty(), "left behind: {left:?}");
    }

    #[test]
    fn staging_is_removed_unless_committed_and_refuses_overwrite() {
        let dir = tempfile::tempdir().expect("tempdir");
        let target = dir.path().join("out");
        {
            let s = Staging::beside(&target);
            fs::create_dir(s.path()).expect("mkdir");
        }
        assert_eq!(fs::read_dir(dir.path()).expect("read_dir").count(), 0);

        fs::create_dir(&target).expect("mkdir");
        let s = Staging::beside(&target);
        fs::create_dir(s.path()).expect("mkdir");
        fs::write(s.path().join("x"), b"1").expect("write");
        let e = s.commit(&target, false).expect_err("must refuse");
        assert_eq!(e.kind(), io::ErrorKind::AlreadyExists);
        assert_eq!(fs::read_dir(dir.path()).expect("read_dir").count(), 1);

        let s = Staging::beside(&target);
        fs::create_dir(s.path()).expect("mkdir");
        fs::write(s.path().join("y"), b"2").expect("write");
        s.commit(&target, true).expect("forced commit");
        assert!(target.join("y").exists() && !target.join("x").exists());
    }
}
