//! `cocog run`: a pipeline file chaining a built-in stage and a plugin stage.

use cocog_synth::{SynthConfig, write_defocus_dataset};
use cocog_tests::{cdylib, cocog, listing, path_str, stderr};
use serde_json::Value;

fn read_scene(dir: &std::path::Path) -> Value {
    let text = std::fs::read_to_string(dir.join("scene.json")).expect("scene.json");
    serde_json::from_str(&text).expect("json")
}

#[test]
fn run_chains_ingest_and_a_plugin_stage() {
    let work = tempfile::tempdir().expect("tempdir");
    write_defocus_dataset(&work.path().join("dataset"), &SynthConfig::tiny(3)).expect("synth");
    let pipeline = work.path().join("pipeline.toml");
    std::fs::write(
        &pipeline,
        "[pipeline]\ninput = \"dataset\"\noutput = \"runs/final\"\n\
         stages = [\"ingest-colmap\", \"recenter\"]\n\n[recenter]\nradius = 1.5\n",
    )
    .expect("write pipeline");
    let lib = cdylib("cocog-plugin-recenter");
    let out = cocog(&["run", path_str(&pipeline), "--plugin-path", path_str(&lib)]);
    assert!(out.status.success(), "{}", stderr(&out));
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.trim_end().ends_with("runs/final"), "{stdout}");

    let runs = work.path().join("runs");
    assert_eq!(listing(&runs), vec!["final", "final.stages"]);
    assert_eq!(
        listing(&runs.join("final.stages")),
        vec!["01-ingest-colmap"]
    );
    let ingested = read_scene(&runs.join("final.stages/01-ingest-colmap"));
    let scene = read_scene(&runs.join("final"));
    let history: Vec<&str> = scene["history"]
        .as_array()
        .expect("history")
        .iter()
        .map(|h| h["stage"].as_str().expect("stage"))
        .collect();
    assert_eq!(history, vec!["ingest-colmap", "recenter"]);
    assert_eq!(scene["views"].as_array().map(Vec::len), Some(10));
    // Same views in the same order, same rotations; only the camera centres moved.
    let pairs = scene["views"]
        .as_array()
        .expect("views")
        .iter()
        .zip(ingested["views"].as_array().expect("views"));
    for (a, b) in pairs {
        for key in ["name", "image", "split", "camera"] {
            assert_eq!(a[key], b[key], "{key}");
        }
        for r in 0..3 {
            for c in 0..3 {
                assert_eq!(a["world_from_camera"][r][c], b["world_from_camera"][r][c]);
            }
        }
    }
    let far = scene["views"]
        .as_array()
        .expect("views")
        .iter()
        .map(|v| {
            let m = &v["world_from_camera"];
            (0..3)
                .map(|r| m[r][3].as_f64().expect("t").powi(2))
                .sum::<f64>()
                .sqrt()
        })
        .fold(0.0, f64::max);
    assert!((far - 1.5).abs() < 1e-9, "farthest camera at {far}");
}

#[test]
fn pipeline_mistakes_fail_before_any_stage_runs() {
    let work = tempfile::tempdir().expect("tempdir");
    std::fs::create_dir(work.path().join("dataset")).expect("mkdir");
    let pipeline = work.path().join("p.toml");
    // Writes `text` as the pipeline and runs it: exit `code` and every needle on stderr.
    let refused = |text: &str, code: i32, needles: &[&str]| {
        std::fs::write(&pipeline, text).expect("write");
        let out = cocog(&["run", path_str(&pipeline)]);
        let err = stderr(&out);
        assert_eq!(out.status.code(), Some(code), "{err}");
        for n in needles {
            assert!(err.contains(n), "{n:?} not in {err}");
        }
    };
    let head = "[pipeline]\ninput = \"dataset\"\noutput = \"out\"\n";

    refused(
        &format!("{head}stages = [\"ingest-colmap\", \"no-such-stage\"]\n"),
        3,
        &["no-such-stage"],
    );
    refused(
        &format!("{head}stages = [\"ingest-colmap\"]\n[densfy]\npoints = 1\n"),
        2,
        &["p.toml", "[densfy]"],
    );
    refused(
        &format!("{head}stages = [\"ingest-colmap\", \"render\", \"eval-scene\"]\n"),
        2,
        &["'render'", "does not write a scene"],
    );
    // An option typo, or a value JSON cannot carry, in a later stage's table.
    refused(
        &format!(
            "{head}stages = [\"ingest-colmap\", \"train\", \"export\"]\n[export]\nformt = \"glb\"\n"
        ),
        2,
        &["no option 'formt'"],
    );
    refused(
        &format!(
            "{head}stages = [\"ingest-colmap\", \"densify\"]\n[densify]\nmax-distance = nan\n"
        ),
        2,
        &["[densify] option 'max-distance': NaN is not a finite number"],
    );
    // A value the last stage refuses stops the run before the first stage, not after it.
    refused(
        &format!(
            "{head}stages = [\"ingest-colmap\", \"train\", \"export\"]\n[export]\nformat = \"obj\"\n"
        ),
        2,
        &["'format': expected ply, glb or spz, got \"obj\""],
    );
    // Stages whose input no earlier stage can give.
    refused(
        &format!("{head}stages = [\"ingest-colmap\", \"train\", \"ingest-llff\"]\n"),
        2,
        &["'ingest-llff' reads a dataset, but it follows 'train'"],
    );
    refused(
        &format!("{head}stages = [\"ingest-colmap\", \"export\"]\n"),
        2,
        &[
            "'export' (export) needs trained Gaussians",
            "no stage since 'ingest-colmap' makes any",
        ],
    );
    // Densify adds points, not Gaussians.
    refused(
        &format!("{head}stages = [\"ingest-colmap\", \"densify\", \"render\"]\n"),
        2,
        &["'render' (render) needs trained Gaussians"],
    );
    // `eval` scores two folders of images and reads no Gaussians, and a plugin stage may make
    // them whatever its kind: neither is refused by the order check, so the run starts and
    // its first stage meets the empty dataset.
    let lib = cdylib("cocog-plugin-recenter");
    for (stages, extra) in [
        ("\"ingest-colmap\", \"eval\"", "[eval]\ngt = \"gt\"\n"),
        ("\"ingest-colmap\", \"recenter\", \"export\"", ""),
    ] {
        std::fs::write(&pipeline, format!("{head}stages = [{stages}]\n{extra}")).expect("write");
        let out = cocog(&["run", path_str(&pipeline), "--plugin-path", path_str(&lib)]);
        let err = stderr(&out);
        assert!(
            !out.status.success()
                && !err.contains("needs trained Gaussians")
                && err.contains("stage 'ingest-colmap'"),
            "{stages}: {err}"
        );
        std::fs::remove_dir_all(work.path().join("out.stages")).ok();
    }
    refused("[pipeline]\ninput = 3\n", 2, &["p.toml"]);
    assert_eq!(listing(work.path()), vec!["dataset", "p.toml"]);
}

#[test]
fn resume_keeps_finished_stages_and_reruns_from_a_changed_option() {
    let work = tempfile::tempdir().expect("tempdir");
    write_defocus_dataset(&work.path().join("dataset"), &SynthConfig::tiny(3)).expect("synth");
    let pipeline = work.path().join("pipeline.toml");
    let write = |radius: f64| {
        std::fs::write(
            &pipeline,
            format!(
                "[pipeline]\ninput = \"dataset\"\noutput = \"final\"\n\
                 stages = [\"ingest-colmap\", \"recenter\"]\n\n[recenter]\nradius = {radius:?}\n"
            ),
        )
        .expect("write pipeline");
    };
    let lib = cdylib("cocog-plugin-recenter");
    let run = |extra: &[&str]| {
        let mut args = vec!["run", path_str(&pipeline), "--plugin-path", path_str(&lib)];
        args.extend(extra);
        cocog(&args)
    };
    write(1.5);
    let out = run(&[]);
    assert!(out.status.success(), "{}", stderr(&out));
    let ingested = work.path().join("final.stages/01-ingest-colmap/scene.json");
    let first = std::fs::metadata(&ingested).unwrap().modified().unwrap();

    // A rerun without --resume or --force refuses rather than redoing anything.
    let out = run(&[]);
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    assert!(stderr(&out).contains("already exists"), "{}", stderr(&out));

    // Nothing changed: everything is kept.
    let out = run(&["--resume"]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert_eq!(stderr(&out).matches("kept").count(), 2, "{}", stderr(&out));

    // The last stage's option changed: ingest is kept, recenter runs again.
    write(2.5);
    let out = run(&["--resume"]);
    let err = stderr(&out);
    assert!(out.status.success(), "{err}");
    assert!(err.contains("[1/2] ingest-colmap: kept"), "{err}");
    assert!(err.contains("[2/2] recenter ->"), "{err}");
    assert_eq!(
        std::fs::metadata(&ingested).unwrap().modified().unwrap(),
        first
    );
    let scene = read_scene(&work.path().join("final"));
    let last = scene["history"].as_array().unwrap().last().unwrap().clone();
    assert_eq!(last["options"]["radius"], 2.5);
}
