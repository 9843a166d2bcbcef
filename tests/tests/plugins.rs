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

/// Runs `cocog` with the constructor fixture's mark file in its environment.
fn cocog_marked(args: &[&str], mark: &Path) -> std::process::Output {
    std::process::Command::new(cocog_tests::cocog_bin())
        .args(args)
        .env("COCOG_TEST_CONSTRUCTOR_MARK", mark)
        .env_remove("COCOG_PLUGIN_PATH")
        .output()
        .expect("run cocog")
}

#[test]
fn libraries_that_are_not_plugins_are_never_opened() {
    let constructor = cdylib("cocog-test-constructor");
    let plugin = cdylib("cocog-test-misbehaving");
    let dir = plugin_dir(&[&constructor, &plugin]);
    let junk = dir
        .path()
        .join(format!("junk{}", std::env::consts::DLL_SUFFIX));
    std::fs::write(&junk, b"this is not a shared library").expect("write");
    let work = tempfile::tempdir().expect("tempdir");
    let mark = work.path().join("constructor-ran");
    let dir_arg = dir.path().to_str().expect("utf-8");

    let out = cocog_marked(&["plugins", "--plugin-path", dir_arg], &mark);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(0), "{err}");
    assert!(err.contains("skipped 2 libraries"), "{err}");
    assert!(cocog_tests::stdout(&out).contains("explode"));
    assert!(!mark.exists(), "discovery ran a non-plugin's constructor");

    // -v names each with its reason.
    let out = cocog_marked(&["plugins", "-v", "--plugin-path", dir_arg], &mark);
    let err = stderr(&out);
    assert!(
        err.contains("junk") && err.contains("not a library"),
        "{err}"
    );
    assert!(
        err.contains("libcocog_test_constructor") && err.contains("does not export"),
        "{err}"
    );

    // Named explicitly it is refused, still unopened.
    let lib_arg = constructor.to_str().expect("utf-8");
    let out = cocog_marked(&["plugins", "--use", &format!("train={lib_arg}")], &mark);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("cocog_plugin_entry"), "{err}");
    assert!(!mark.exists(), "--use ran a non-plugin's constructor");

    // The control: loading the fixture does leave the mark, so the checks above can fail.
    if cfg!(target_os = "linux") {
        let loaded = std::process::Command::new("python3")
            .args([
                "-c",
                "import ctypes, sys; ctypes.CDLL(sys.argv[1])",
                lib_arg,
            ])
            .env("COCOG_TEST_CONSTRUCTOR_MARK", &mark)
            .status();
        match loaded {
            Ok(status) if status.success() => assert!(mark.exists()),
            _ => eprintln!("control skipped: python3 could not load the fixture"),
        }
    }
}

#[test]
fn cargo_deps_copies_count_once_and_missing_dirs_are_named() {
    let plugin = cdylib("cocog-test-misbehaving");
    let dir = plugin_dir(&[&plugin]);
    let deps = dir.path().join("deps");
    std::fs::create_dir(&deps).expect("mkdir");
    std::fs::copy(&plugin, deps.join(plugin.file_name().expect("name"))).expect("copy");
    let out = cocog(&[
        "plugins",
        "--plugin-path",
        dir.path().to_str().expect("utf-8"),
    ]);
    let table = cocog_tests::stdout(&out);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    assert_eq!(
        table.lines().filter(|l| l.starts_with("explode ")).count(),
        1,
        "{table}"
    );
    // `deps/` on its own still finds it.
    let out = cocog(&["plugins", "--plugin-path", deps.to_str().expect("utf-8")]);
    assert!(cocog_tests::stdout(&out).contains("explode"));
    // Cargo hard-links the two: one file, met first in `deps/`, still listed once.
    let name = plugin.file_name().expect("name");
    std::fs::remove_file(deps.join(name)).expect("rm");
    std::fs::hard_link(dir.path().join(name), deps.join(name)).expect("hard link");
    let out = cocog(&[
        "plugins",
        "--plugin-path",
        dir.path().to_str().expect("utf-8"),
    ]);
    let table = cocog_tests::stdout(&out);
    assert_eq!(
        table.lines().filter(|l| l.starts_with("explode ")).count(),
        1,
        "{table}"
    );

    let missing = dir.path().join("no-such-dir");
    let out = cocog(&["plugins", "--plugin-path", missing.to_str().expect("utf-8")]);
    assert_eq!(out.status.code(), Some(1));
    assert!(stderr(&out).contains("no-such-dir"), "{}", stderr(&out));
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

#[cfg(target_os = "linux")]
#[test]
fn a_plugin_the_loader_refuses_is_reported_with_the_loader_message() {
    // The plugin built for another CPU: its export table still reads, dlopen refuses it.
    let plugin = cdylib("cocog-test-misbehaving");
    let dir = tempfile::tempdir().expect("tempdir");
    let copy = dir.path().join(plugin.file_name().expect("name"));
    let mut bytes = std::fs::read(&plugin).expect("read plugin");
    let other_machine: u16 = if cfg!(target_arch = "aarch64") {
        62
    } else {
        183
    };
    bytes[18..20].copy_from_slice(&other_machine.to_le_bytes());
    std::fs::write(&copy, bytes).expect("write");
    let out = cocog(&[
        "plugins",
        "--plugin-path",
        dir.path().to_str().expect("utf-8"),
    ]);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{err}");
    let line = err
        .lines()
        .find(|l| l.contains("dlopen failed"))
        .unwrap_or_else(|| panic!("no loader error in: {err}"));
    // The loader's own words follow libloading's "dlopen failed: ".
    let (_, reason) = line.split_once("dlopen failed: ").expect("a reason");
    assert!(reason.contains("libcocog_test_misbehaving"), "{line}");
}
