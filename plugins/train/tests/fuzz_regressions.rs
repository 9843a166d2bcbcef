//! Inputs that once broke a reader under `fuzz/run`, kept in `fuzz/regressions/<target>/` and
//! replayed by every `cargo test`: each must be read or refused with an error, never panic,
//! abort or hang. A new finding needs no code here: save the file in its target's folder.

use std::path::{Path, PathBuf};
use std::sync::mpsc;
use std::time::Duration;

/// The saved inputs of fuzz target `target`, sorted; none if the folder does not exist.
fn cases(target: &str) -> Vec<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../fuzz/regressions")
        .join(target);
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .map(|d| d.map(|e| e.expect("list regressions").path()).collect())
        .unwrap_or_default();
    files.retain(|p| p.is_file());
    files.sort();
    files
}

/// Runs `read` on every saved input of `target`, each within 30 s (the fuzzer's hang limit is
/// 10 s; the margin is for slow debug builds). A panic fails the test naming the input.
fn replay(target: &str, read: fn(&[u8])) {
    for case in cases(target) {
        let data = std::fs::read(&case).expect("read regression input");
        let (done, finished) = mpsc::channel();
        let name = case.display().to_string();
        let worker = std::thread::spawn(move || {
            read(&data);
            let _ = done.send(());
        });
        match finished.recv_timeout(Duration::from_secs(30)) {
            Ok(()) => worker.join().expect("reader thread"),
            Err(mpsc::RecvTimeoutError::Timeout) => panic!("{name}: the reader hangs"),
            Err(mpsc::RecvTimeoutError::Disconnected) => {
                panic!("{name}: the reader panicked (message above)")
            }
        }
    }
}

/// Writes `data` as `name` in a fresh folder and returns the folder and the file.
fn staged(name: &str, data: &[u8]) -> (tempfile::TempDir, PathBuf) {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join(name);
    std::fs::write(&path, data).expect("write input");
    (dir, path)
}

#[test]
fn checkpoint_regressions() {
    replay("checkpoint", |data| {
        let (_dir, path) = staged(cocog_train::CHECKPOINT_FILE, data);
        let _ = cocog_train::TrainState::load(&path);
    });
}
