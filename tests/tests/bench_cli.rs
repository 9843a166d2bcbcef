//! `cocog bench --synthetic`: speed on random Gaussians without a dataset, at a fixed count,
//! and its usage errors.

use std::path::Path;
use std::process::Command;

use cocog_tests::{cocog, path_str, stderr, stdout};

/// Whether python3 imports `modules`; absent → skip (printed), except under CI=true.
fn python_has(modules: &str) -> bool {
    let ok = Command::new("python3")
        .args(["-c", &format!("import {modules}")])
        .output()
        .is_ok_and(|o| o.status.success());
    assert!(
        ok || std::env::var("CI").as_deref() != Ok("true"),
        "CI=true but python3 cannot import {modules}"
    );
    ok
}

#[test]
fn a_synthetic_workload_keeps_its_count_and_size() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let workload = tmp.path().join("workload");
    let out = cocog(&[
        "bench",
        "--write-workload",
        path_str(&workload),
        "--synthetic",
        "3000",
        "--size",
        "96x64",
        "--views",
        "4",
        "--sh-degree",
        "2",
        "--iterations",
        "3",
        "--warmup",
        "3",
        "--json",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let report: serde_json::Value = serde_json::from_str(&stdout(&out)).expect("bench JSON");
    for (field, want) in [
        ("gaussians_start", 3000),
        ("gaussians_end", 3000),
        ("width", 96),
        ("height", 64),
        ("views", 4),
        ("iterations", 3),
    ] {
        assert_eq!(report[field], want, "{field}: {report}");
    }
    assert!(
        report["source"].as_str().unwrap().contains("3000 random"),
        "{report}"
    );
    let ms = report["ms_per_iteration"].as_f64().unwrap();
    assert!(ms.is_finite() && ms > 0.0, "{report}");
    // No density control and a warm workspace: a step allocates nothing and submits once.
    let ops = &report["per_iteration"];
    assert_eq!(ops["buffers_created"], 0.0, "{report}");
    assert_eq!(ops["blocking_reads"], 0.0, "{report}");
    assert_eq!(ops["submissions"], 1.0, "{report}");

    // The peer script reads the same workload back (INRIA PLY through plyfile) and finds every
    // Gaussian in every camera's frame.
    if !python_has("numpy, plyfile") {
        return;
    }
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../bench/peer_gsplat.py");
    let check = Command::new("python3")
        .args([
            path_str(&script),
            "check",
            "--workload",
            path_str(&workload),
        ])
        .output()
        .expect("python3");
    let said = stdout(&check);
    assert!(check.status.success(), "{said}{}", stderr(&check));
    assert!(
        said.contains("workload: 3000 Gaussians, SH degree 2, 4 cameras of 96x64"),
        "{said}"
    );
    assert_eq!(
        said.matches("1.000 of the points in its frame").count(),
        4,
        "{said}"
    );
}

#[test]
fn bench_usage_errors_say_what_was_expected() {
    for (args, said) in [
        (&["bench"][..], "<SCENE|--synthetic <N>>"),
        (
            &["bench", "--synthetic", "10", "--size", "96"],
            "WIDTHxHEIGHT",
        ),
        (
            &["bench", "--synthetic", "10", "--size", "0x64"],
            "WIDTHxHEIGHT",
        ),
        (&["bench", "--synthetic", "0"], "--synthetic"),
        (
            &["bench", "somewhere", "--synthetic", "10"],
            "cannot be used with",
        ),
        (
            &["bench", "somewhere", "--size", "96x64"],
            "cannot be used with",
        ),
    ] {
        let out = cocog(args);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {}", stderr(&out));
        assert!(stderr(&out).contains(said), "{args:?}: {}", stderr(&out));
    }
}

fn bench_4000x3000(method: &str) -> std::process::Output {
    cocog(&[
        "bench",
        "--synthetic",
        "10",
        "--size",
        "4000x3000",
        "--views",
        "2",
        "--sh-degree",
        "0",
        "--iterations",
        "1",
        "--warmup",
        "0",
        "--method",
        method,
    ])
}

/// A 4000×3000 photo's rgba render needs 183 MiB, more than lavapipe binds (128 MiB): plain
/// 3DGS trains it in bands of rows, one submission per band and one for the optimiser.
#[test]
fn photos_larger_than_a_binding_train_in_bands() {
    let out = bench_4000x3000("3dgs");
    let said = stdout(&out);
    assert!(out.status.success(), "{said}{}", stderr(&out));
    let submissions: f64 = said
        .lines()
        .find_map(|l| l.strip_prefix("engine ops/it"))
        .and_then(|l| l.split('|').find(|f| f.contains("submissions")))
        .and_then(|f| f.split_whitespace().next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no submission count in {said}"));
    if said.contains("llvmpipe") {
        assert_eq!(
            submissions, 3.0,
            "two bands and the optimiser on lavapipe: {said}"
        );
        assert!(said.contains("trained in 2 bands of rows"), "{said}");
    }
}

/// A cocog step cannot band (F's instance norms see whole frames): the same photo is refused
/// up front with the sizes and a way out, never a panic.
#[test]
fn cocog_photos_too_large_for_a_binding_are_a_clear_error() {
    let out = bench_4000x3000("cocog");
    let said = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{said}");
    assert!(
        said.contains("4000×3000 photos need a") && said.contains("--downscale"),
        "{said}"
    );
}
