//! Helpers shared by the integration tests: locating the bench data and running Python cross-checks.
#![allow(dead_code)]

use std::path::PathBuf;
use std::process::Command;

/// `<workspace root>/../shared`, where the team's reference data lives.
pub fn shared_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared")
}

/// The two defocus dev scenes, or an empty list (with the reason printed) when the data is absent.
pub fn dev_scenes() -> Vec<PathBuf> {
    let root = shared_dir().join("bench/defocus-dev");
    let scenes: Vec<PathBuf> = ["dev-table", "dev-shelf"]
        .iter()
        .map(|s| root.join(s))
        .filter(|p| p.is_dir())
        .collect();
    if scenes.is_empty() {
        eprintln!("SKIP: bench data not found at {}", root.display());
    }
    scenes
}

fn in_ci() -> bool {
    std::env::var("CI").is_ok_and(|v| v == "true")
}

/// Whether `python3` can import every module. Absent → skip (printed), except under CI=true,
/// where the cross-check is required and a missing module fails the test.
pub fn python_has(modules: &[&str]) -> bool {
    let import = format!("import {}", modules.join(", "));
    let ok = Command::new("python3")
        .args(["-c", &import])
        .output()
        .is_ok_and(|o| o.status.success());
    if !ok {
        assert!(
            !in_ci(),
            "CI=true but python3 cannot `{import}`: install the Python reference modules"
        );
        eprintln!("SKIP: python3 cannot `{import}`");
    }
    ok
}

/// Runs a Python script with arguments and returns its stdout; fails the test on a non-zero exit.
pub fn run_python(script: &str, args: &[&str]) -> String {
    let out = Command::new("python3")
        .arg("-c")
        .arg(script)
        .args(args)
        .output()
        .expect("python3 runs");
    assert!(
        out.status.success(),
        "python failed:\n{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).expect("python prints UTF-8")
}
