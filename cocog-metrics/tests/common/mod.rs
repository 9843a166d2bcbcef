//! Locating the shared data and external references, and the skip-or-fail rule: a missing
//! prerequisite skips a test with a printed reason, except under `CI=true`, where it fails.

#![allow(dead_code)] // Each test binary uses a different subset.

use std::path::PathBuf;
use std::process::Command;

/// True when running in CI, where nothing may be skipped.
pub fn in_ci() -> bool {
    std::env::var("CI").is_ok_and(|v| v == "true")
}

/// Prints why a test cannot run and returns, or panics in CI.
pub fn skip(test: &str, reason: &str) {
    assert!(!in_ci(), "{test}: {reason} (CI=true, so this is a failure)");
    eprintln!("SKIP {test}: {reason}");
}

/// `<workspace root>/../shared`, if present.
pub fn shared_dir() -> Option<PathBuf> {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..");
    let shared = root.join("../shared");
    shared
        .is_dir()
        .then(|| shared.canonicalize().unwrap_or(shared))
}

/// Runs `python3 -c script args...` and returns stdout, or the reason it could not run (missing
/// interpreter or module). A script that fails for another reason panics: that is a test bug.
pub fn python(script: &str, args: &[String]) -> Result<String, String> {
    let out = Command::new("python3")
        .arg("-c")
        .arg(script)
        .args(args)
        .output()
        .map_err(|e| format!("python3 not runnable: {e}"))?;
    let stderr = String::from_utf8_lossy(&out.stderr);
    if !out.status.success() {
        if stderr.contains("ModuleNotFoundError") {
            return Err(format!(
                "python module missing: {}",
                stderr.lines().last().unwrap_or("")
            ));
        }
        panic!("python reference script failed:\n{stderr}");
    }
    Ok(String::from_utf8(out.stdout).expect("python prints UTF-8"))
}
