//! Dynamic plugins through the real discovery path: built as cdylibs, found on
//! `--plugin-path`, and every way a plugin can be broken turned into a clean error.

use std::path::Path;

use cocog_tests::{cdylib, cocog, listing, stderr};

/// A plugin directory holding copies of the given libraries.
fn plugin_dir(libs: &[&Path]) -> tempfile::TempDir {
    let dir = tempfile::tempdir().expect("tempdir");
    for lib in libs {
        let name = lib.file_name().expect("library file name");
        std::fs::copy(lib, dir.path().join(name)).expect("copy plugin");
    }
    dir
}

#[test]
fn wrong_abi_version_is_refused_by_file_name() {
    let lib = cdylib("cocog-test-wrong-abi");
    let dir = plugin_dir(&[&lib]);
    let dir_arg = dir.path().to_str().expect("utf-8 path");
    let out = cocog(&["plugins", "--plugin-path", dir_arg]);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("libcocog_test_wrong_abi"), "{err}");
    assert!(
        err.contains("ABI version 999") && err.contains("speaks ABI version 1"),
        "{err}"
    );

    // Asking for it explicitly is fatal, and names the file too.
    let lib_arg = lib.to_str().expect("utf-8 path");
    let out = cocog(&["plugins", "--use", &format!("train={lib_arg}")]);
    assert_eq!(out.status.code(), Some(1));
    assert!(stderr(&out).contains("ABI version 999"), "{}", stderr(&out));
}

#[test]
fn a_panicking_stage_is_an_error_and_leaves_nothing_behind() {
    let lib = cdylib("cocog-test-misbehaving");
    let dir = plugin_dir(&[&lib]);
    let work = tempfile::tempdir().expect("tempdir");
    let input = work.path().join("in");
    std::fs::create_dir(&input).expect("mkdir");
    let output = work.path().join("out");
    let out = cocog(&[
        "stage",
        "explode",
        input.to_str().expect("utf-8"),
        "-o",
        output.to_str().expect("utf-8"),
        "--plugin-path",
        dir.path().to_str().expect("utf-8"),
    ]);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("stage 'explode' failed: panicked: deliberate panic"),
        "{err}"
    );
    assert!(err.contains("libcocog_test_misbehaving"), "{err}");
    assert_eq!(
        err.lines().filter(|l| l.starts_with("error:")).count(),
        1,
        "{err}"
    );
    // The stage wrote partial.txt into its staging directory before panicking.
    assert_eq!(listing(work.path()), vec!["in".to_owned()]);
}

#[test]
fn a_failing_stage_reports_its_message_and_the_plugin_file() {
    let lib = cdylib("cocog-test-misbehaving");
    let work = tempfile::tempdir().expect("tempdir");
    let out = cocog(&[
        "stage",
        "refuse",
        work.path().to_str().expect("utf-8"),
        "-o",
        work.path().join("out").to_str().expect("utf-8"),
        "--plugin-path",
        lib.to_str().expect("utf-8"),
    ]);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("field `views`") && err.contains("[plugin "),
        "{err}"
    );
    assert!(!work.path().join("out").exists());
}

#[test]
fn files_that_are_not_plugins_are_named_with_the_cause() {
    let dir = tempfile::tempdir().expect("tempdir");
    let junk = dir
        .path()
        .join(format!("junk{}", std::env::consts::DLL_SUFFIX));
    std::fs::write(&junk, b"this is not a shared library").expect("write");
    let out = cocog(&[
        "plugins",
        "--plugin-path",
        dir.path().to_str().expect("utf-8"),
    ]);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("junk") && err.contains("cannot load as a library"),
        "{err}"
    );

    let missing = dir.path().join("no-such-dir");
    let out = cocog(&["plugins", "--plugin-path", missing.to_str().expect("utf-8")]);
    assert!(stderr(&out).contains("no-such-dir"), "{}", stderr(&out));
}

#[test]
fn a_library_without_the_entry_symbol_is_refused() {
    // Any real shared library that is not a cocog plugin will do.
    let candidates = [
        "/lib/x86_64-linux-gnu/libm.so.6",
        "/usr/lib/x86_64-linux-gnu/libm.so.6",
        "/lib/aarch64-linux-gnu/libm.so.6",
        "/usr/lib/aarch64-linux-gnu/libm.so.6",
    ];
    let Some(libm) = candidates.iter().map(Path::new).find(|p| p.exists()) else {
        eprintln!("skipped: no libm.so.6 found to stand in for a non-plugin library");
        return;
    };
    let dir = tempfile::tempdir().expect("tempdir");
    std::fs::copy(libm, dir.path().join("libm.so")).expect("copy");
    let out = cocog(&[
        "plugins",
        "--plugin-path",
        dir.path().to_str().expect("utf-8"),
    ]);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("libm.so") && err.contains("cocog_plugin_entry"),
        "{err}"
    );
}

#[test]
fn a_plugin_replaces_a_built_in_only_when_asked() {
    let lib = cdylib("cocog-test-misbehaving");
    let dir = plugin_dir(&[&lib]);
    let plugin_dir_arg = dir.path().to_str().expect("utf-8");
    let listing_out = cocog(&["plugins", "--plugin-path", plugin_dir_arg]);
    let table = cocog_tests::stdout(&listing_out);
    let eval_rows: Vec<&str> = table.lines().filter(|l| l.starts_with("eval ")).collect();
    assert_eq!(eval_rows.len(), 2, "{table}");
    assert!(
        eval_rows
            .iter()
            .any(|r| r.contains("built-in") && !r.contains("inactive")),
        "{table}"
    );
    assert!(
        eval_rows
            .iter()
            .any(|r| r.contains("misbehaving (inactive)")),
        "{table}"
    );

    let work = tempfile::tempdir().expect("tempdir");
    let (pred, gt) = (work.path().join("pred"), work.path().join("gt"));
    std::fs::create_dir(&pred).expect("mkdir");
    std::fs::create_dir(&gt).expect("mkdir");
    let args = |extra: &[&'static str]| {
        let mut v = vec![
            "eval".to_owned(),
            "--pred".to_owned(),
            pred.display().to_string(),
            "--gt".to_owned(),
            gt.display().to_string(),
            "--plugin-path".to_owned(),
            plugin_dir_arg.to_owned(),
        ];
        v.extend(extra.iter().map(|s| (*s).to_owned()));
        v
    };
    let run = |a: Vec<String>| cocog(&a.iter().map(String::as_str).collect::<Vec<_>>());
    // Without --use the built-in runs (and complains about the empty folder itself).
    let out = run(args(&[]));
    assert!(
        !stderr(&out).contains("misbehaving plugin's eval ran"),
        "{}",
        stderr(&out)
    );
    let out = run(args(&["--use", "eval=misbehaving"]));
    assert!(
        stderr(&out).contains("misbehaving plugin's eval ran"),
        "{}",
        stderr(&out)
    );
    let out = run(args(&["--use", "eval=nobody"]));
    assert!(
        stderr(&out).contains("no loaded plugin named 'nobody'"),
        "{}",
        stderr(&out)
    );
}
