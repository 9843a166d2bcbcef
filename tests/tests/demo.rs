//! `cocog demo` runs the chain on its generated dataset, as the README promises.

use cocog_tests::{cocog, listing, path_str, stderr, stdout};

#[test]
fn demo_generates_its_dataset_and_runs_the_available_stages() {
    let work = tempfile::tempdir().expect("tempdir");
    let root = work.path().join("demo");
    // A shortened run: the default (1200 iterations per method) is the ten-minute demo.
    let out = cocog(&["demo", "-o", path_str(&root), "--iterations", "40"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let names = listing(&root);
    for expected in [
        "1-ingest",
        "2-densify",
        "3-train-3dgs",
        "4-train-cocog",
        "5-prune",
        "dataset",
        "scene.ply",
        "scene.glb",
        "scene.spz",
        "metrics-3dgs.json",
        "metrics-cocog.json",
        "refocus.gif",
    ] {
        assert!(names.contains(&expected.to_owned()), "{names:?}");
    }
    assert_eq!(listing(&root.join("dataset/images")).len(), 16);
    // Stdout is the exported scene; stderr has the comparison, the lens table and no false
    // alarm.
    let last = stdout(&out);
    assert!(last.trim().ends_with("scene.ply"), "{last}");
    let log = stderr(&out);
    assert!(log.contains("PSNR dB"), "{log}");
    assert!(
        log.contains("cocog beats plain 3DGS") || log.contains("cocog trails plain 3DGS"),
        "{log}"
    );
    assert!(log.contains("median relative focus error"), "{log}");
    assert!(!log.contains("error:"), "{log}");
    assert!(root.join("4-train-cocog/lens-model.safetensors").exists());
    assert!(
        root.join("3-train-3dgs/checkpoint/state.safetensors")
            .exists()
    );
    let gif = std::fs::read(root.join("refocus.gif")).expect("gif");
    assert_eq!(&gif[..4], b"GIF8");
    for method in ["3dgs", "cocog"] {
        let path = root.join(format!("metrics-{method}.json"));
        let metrics: serde_json::Value =
            serde_json::from_slice(&std::fs::read(&path).expect("metrics")).expect("JSON");
        let psnr = metrics["mean"]["psnr"].as_f64().expect("mean PSNR");
        assert!(psnr.is_finite() && psnr > 10.0, "{method}: {metrics}");
        assert_eq!(metrics["views"], 2, "{method}: {metrics}");
    }

    // The benchmark runs on the demo's scene and reports every phase.
    let ingested = root.join("1-ingest");
    let bench = cocog(&[
        "bench",
        path_str(&ingested),
        "--iterations",
        "3",
        "--warmup",
        "1",
        "--json",
    ]);
    assert!(bench.status.success(), "{}", stderr(&bench));
    let report: serde_json::Value = serde_json::from_str(&stdout(&bench)).expect("bench JSON");
    assert!(report["gaussians_start"].as_u64().unwrap() > 0, "{report}");
    assert!(report["peak_gpu_bytes"].as_u64().unwrap() > 0, "{report}");
    for phase in ["forward", "backward", "optimizer", "density"] {
        let ms = report["phases_ms"][phase].as_f64().unwrap();
        assert!(ms.is_finite() && ms >= 0.0, "{phase}: {report}");
    }
    assert!(report["phases_ms"]["forward"].as_f64().unwrap() > 0.0);
    // A rerun replaces the demo's own directory without --force...
    let again = cocog(&["demo", "-o", path_str(&root), "--iterations", "8"]);
    assert!(again.status.success(), "{}", stderr(&again));
    // ...but never a directory it did not make.
    let foreign = work.path().join("mine");
    std::fs::create_dir(&foreign).expect("mkdir");
    let refused = cocog(&["demo", "-o", path_str(&foreign)]);
    assert_eq!(refused.status.code(), Some(1));
    assert!(
        stderr(&refused).contains("not a cocog demo directory"),
        "{}",
        stderr(&refused)
    );
}
