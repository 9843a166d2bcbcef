//! The `eval` stage through the pipeline runner: what lands on disk, what it returns, and how bad
//! input is refused.

use std::path::{Path, PathBuf};

use cocog_pipeline::runner::{RunError, run_stage};
use cocog_pipeline::{NullContext, Registry, StageError};
use serde_json::{Map, Value, json};

fn in_ci() -> bool {
    std::env::var("CI").is_ok_and(|v| v == "true")
}

fn skip(test: &str, reason: &str) {
    assert!(!in_ci(), "{test}: {reason} (CI=true, so this is a failure)");
    eprintln!("SKIP {test}: {reason}");
}

fn shared_dir() -> Option<PathBuf> {
    let shared = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared");
    shared.is_dir().then_some(shared)
}

fn run(pred: &Path, out: &Path, options: Value) -> Result<Value, RunError> {
    let mut registry = Registry::new();
    registry.add_builtins(cocog_eval::stages());
    let entry = registry.resolve("eval").expect("eval is registered");
    let given: Map<String, Value> = options.as_object().cloned().unwrap();
    run_stage(entry, pred, out, &given, false, &NullContext)
}

fn stage_error(e: RunError) -> StageError {
    match e {
        RunError::Stage { source, .. } => source,
        other => panic!("expected a stage error, got {other}"),
    }
}

fn save_rgb(path: &Path, w: u32, h: u32, f: impl Fn(u32, u32) -> [u8; 3]) {
    image::RgbImage::from_fn(w, h, |x, y| image::Rgb(f(x, y)))
        .save(path)
        .unwrap();
}

/// Two synthetic folders of two 40×32 images each, the second pair shifted by one level.
fn synthetic() -> (tempfile::TempDir, PathBuf, PathBuf) {
    let root = tempfile::tempdir().unwrap();
    let (pred, gt) = (root.path().join("pred"), root.path().join("gt"));
    std::fs::create_dir_all(&pred).unwrap();
    std::fs::create_dir_all(&gt).unwrap();
    for (name, offset) in [("a", 0u8), ("b", 1)] {
        let pattern = |x: u32, y: u32| [(x * 6) as u8, (y * 7) as u8, ((x + y) * 3) as u8];
        save_rgb(&gt.join(format!("{name}.png")), 40, 32, pattern);
        save_rgb(&pred.join(format!("{name}.png")), 40, 32, |x, y| {
            pattern(x, y).map(|v| v + offset)
        });
    }
    (root, pred, gt)
}

#[test]
fn writes_metrics_json_equal_to_the_summary() {
    let (root, pred, gt) = synthetic();
    let out = root.path().join("metrics.json");
    let summary = run(&pred, &out, json!({"gt": gt, "lpips": "off"})).unwrap();
    // Compared as text: serde_json's default float parser is not always exact to the last bit.
    let on_disk = std::fs::read_to_string(&out).unwrap();
    assert_eq!(
        on_disk.trim_end(),
        serde_json::to_string_pretty(&summary).unwrap()
    );
    assert_eq!(summary["format"], "cocog-metrics");
    assert_eq!(summary["count"], 2);
    let images = summary["images"].as_array().unwrap();
    assert_eq!(images[0]["name"], "a");
    assert_eq!(
        (images[0]["width"].as_u64(), images[0]["height"].as_u64()),
        (Some(40), Some(32))
    );
    // Identical pair: infinite PSNR is written as null; off-by-one-level pair: 20·log10(255).
    assert!(images[0]["psnr"].is_null());
    let want = 20.0 * 255f64.log10();
    assert!((images[1]["psnr"].as_f64().unwrap() - want).abs() < 1e-9);
    assert!(
        summary["conventions"]["ssim_deblurnerf"]
            .as_str()
            .unwrap()
            .contains("7x7")
    );
    assert!(summary["mean"].get("lpips_alex").is_none());

    let table = cocog_eval::format_table(&summary);
    assert!(
        table.contains("mean (2)") && table.contains("inf"),
        "{table}"
    );
}

#[test]
fn missing_weights_in_auto_mode_reports_how_to_get_them() {
    let (root, pred, gt) = synthetic();
    let empty = root.path().join("no-weights");
    std::fs::create_dir_all(&empty).unwrap();
    let out = root.path().join("m.json");
    let summary = run(&pred, &out, json!({"gt": gt, "lpips_weights": empty})).unwrap();
    let note = summary["lpips"]["note"].as_str().unwrap();
    assert!(
        note.contains("fetch-weights.sh") && note.contains("no-weights"),
        "{note}"
    );
    assert!(summary["images"][0].get("lpips_alex").is_none());

    let out = root.path().join("m2.json");
    let err = run(
        &pred,
        &out,
        json!({"gt": gt, "lpips_weights": empty, "lpips": "require"}),
    );
    assert!(err.unwrap_err().to_string().contains("not found"));
    assert!(!out.exists());
}

#[test]
fn bad_input_is_refused_naming_files_and_nothing_is_written() {
    let (root, pred, gt) = synthetic();
    let out = root.path().join("metrics.json");

    save_rgb(&gt.join("a.png"), 41, 32, |_, _| [0, 0, 0]);
    let err = stage_error(run(&pred, &out, json!({"gt": gt, "lpips": "off"})).unwrap_err());
    let msg = err.to_string();
    assert!(matches!(err, StageError::Input(_)), "{err:?}");
    assert!(
        msg.contains("a.png") && msg.contains("40x32") && msg.contains("41x32"),
        "{msg}"
    );
    assert!(!out.exists());

    std::fs::remove_file(gt.join("a.png")).unwrap();
    let err = stage_error(run(&pred, &out, json!({"gt": gt, "lpips": "off"})).unwrap_err());
    assert!(
        err.to_string().contains("no ground truth for 1 prediction"),
        "{err}"
    );

    let err = stage_error(run(&pred, &out, json!({"gt": gt, "lpips": "maybe"})).unwrap_err());
    assert!(matches!(err, StageError::Options(_)), "{err:?}");
    assert!(!out.exists());
}

/// The do-nothing baseline of a real scene: its PSNR is recorded independently in lens.json, and
/// the LPIPS the stage reports must be the library's value for the same files.
#[test]
fn scores_the_recorded_baseline_of_a_real_scene() {
    let name = "scores_the_recorded_baseline_of_a_real_scene";
    let Some(shared) = shared_dir() else {
        return skip(name, "../shared/bench not found");
    };
    let scene = shared.join("bench/defocus-dev/dev-table");
    let root = tempfile::tempdir().unwrap();
    let out = root.path().join("metrics.json");
    let lpips = cocog_metrics::Lpips::load(cocog_metrics::Net::Alex).ok();
    let mode = if lpips.is_some() { "require" } else { "off" };
    let summary = run(
        &scene.join("baseline"),
        &out,
        json!({"gt": scene.join("images"), "lpips": mode}),
    )
    .unwrap();
    let lens: Value =
        serde_json::from_str(&std::fs::read_to_string(scene.join("lens.json")).unwrap()).unwrap();
    let recorded = lens["baseline"]["psnr_per_view"].as_object().unwrap();
    let images = summary["images"].as_array().unwrap();
    assert_eq!(
        images.len(),
        recorded.len(),
        "extra ground-truth views are ignored"
    );
    for img in images {
        let want = recorded[&format!("{}.png", img["name"].as_str().unwrap())]
            .as_f64()
            .unwrap();
        assert!((img["psnr"].as_f64().unwrap() - want).abs() < 6e-5, "{img}");
    }
    let Some(model) = lpips else {
        return skip(name, "LPIPS weights not installed: LPIPS part not checked");
    };
    let img = &images[0];
    let load = |k: &str| cocog_metrics::load_image(Path::new(img[k].as_str().unwrap())).unwrap();
    let direct = model.distance(&load("pred"), &load("gt")).unwrap();
    assert!((img["lpips_alex"].as_f64().unwrap() - direct).abs() < 1e-12);
}
