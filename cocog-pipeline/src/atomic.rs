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

/// Removes hidden siblings of `target` left by cocog processes that no longer run (a run
/// killed with SIGKILL cannot clean up after itself). Only on Linux, where `/proc` tells
/// whether a process lives; elsewhere they stay, which is safe.
pub fn remove_stale_temps(target: &Path) {
    let (Some(name), parent) = (target.file_name(), target.parent()) else {
        return;
    };
    let parent = parent
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or_else(|| Path::new("."));
    let prefix = format!(".{}.cocog-tmp-", name.to_string_lossy());
    let Ok(entries) = fs::read_dir(parent) else {
        return;
    };
    for entry in entries.flatten() {
        let file_name = entry.file_name();
        let Some(pid) = file_name
            .to_str()
            .and_then(|n| n.strip_prefix(&prefix))
            .and_then(|rest| rest.split('-').next())
            .and_then(|pid| pid.parse::<u32>().ok())
        else {
            continue;
        };
        if pid != std::process::id() && process_is_gone(pid) {
            let _ = remove_any(&entry.path());
        }
    }
}

/// A scratch folder beside `output`, removed when dropped. Its name extends `output`'s, so
/// when `output` is a stage's staging path (`sibling_temp`) and the process is killed before
/// the drop, the next run's `remove_stale_temps` of the same target removes it too.
pub fn scratch_beside(output: &Path) -> io::Result<tempfile::TempDir> {
    let name = output
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "output".to_owned());
    let parent = output
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or_else(|| Path::new("."));
    let prefix = if name.starts_with('.') {
        format!("{name}-scratch-")
    } else {
        format!(".{name}-scratch-")
    };
    tempfile::Builder::new().prefix(&prefix).tempdir_in(parent)
}

fn process_is_gone(pid: u32) -> bool {
    cfg!(target_os = "linux")
        && Path::new("/proc/self").exists()
        && !Path::new(&format!("/proc/{pid}")).exists()
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

    #[cfg(target_os = "linux")]
    #[test]
    fn temps_of_dead_processes_are_removed_and_live_ones_kept() {
        let dir = tempfile::tempdir().expect("tempdir");
        let target = dir.path().join("out");
        // A pid that cannot exist (above the kernel's pid_max limit of 2^22).
        let dead = dir.path().join(".out.cocog-tmp-4194305-0");
        let live = dir
            .path()
            .join(format!(".out.cocog-tmp-{}-0", std::process::id()));
        let other = dir.path().join(".other.cocog-tmp-4194305-0");
        for d in [&dead, &live, &other] {
            fs::create_dir(d).expect("mkdir");
            fs::write(d.join("x"), b"1").expect("write");
        }
        remove_stale_temps(&target);
        assert!(!dead.exists());
        assert!(live.exists() && other.exists());
    }

    #[cfg(target_os = "linux")]
    #[test]
    fn scratch_beside_a_dead_runs_staging_goes_with_its_stale_temps() {
        let dir = tempfile::tempdir().expect("tempdir");
        let target = dir.path().join("eval.json");
        let dead_staging = dir.path().join(".eval.json.cocog-tmp-4194305-3");
        let scratch = scratch_beside(&dead_staging).expect("scratch");
        fs::write(scratch.path().join("x"), b"1").expect("write");
        // As if the process had been killed: the folder outlives its TempDir.
        let kept = scratch.keep();
        let live = scratch_beside(&sibling_temp(&target)).expect("scratch");
        remove_stale_temps(&target);
        assert!(!kept.exists(), "{}", kept.display());
        assert!(live.path().exists());
        drop(live);
        assert_eq!(fs::read_dir(dir.path()).expect("read_dir").count(), 0);
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
