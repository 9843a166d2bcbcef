//! Training you can watch: the log grows beside the output while the run goes on, progress
//! lines come by time when stderr is no terminal, the test views are scored with
//! `--eval-every`, and every stage command's `--json` names its output.

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use cocog_synth::{SynthConfig, write_defocus_dataset};
use cocog_tests::{cocog, cocog_bin, path_str, stderr, stdout};
use serde_json::Value;

fn records(log: &str) -> Vec<Value> {
    log.lines()
        .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("{e}: {l}")))
        .collect()
}

/// Runs `cocog ARGS --json` and returns its result, which must name `output`.
fn json_result(args: &[&str], output: &Path) -> Value {
    let mut args = args.to_vec();
    args.push("--json");
    let out = cocog(&args);
    assert!(out.status.success(), "{args:?}: {}", stderr(&out));
    let v: Value = serde_json::from_str(&stdout(&out)).expect("JSON result");
    assert_eq!(v["output"], path_str(output), "{args:?}: {v}");
    v
}

#[test]
fn the_log_is_watchable_while_training_and_scored_with_eval_every() {
    let work = tempfile::tempdir().expect("tempdir");
    let p = |name: &str| work.path().join(name);
    write_defocus_dataset(&p("data"), &SynthConfig::tiny(2)).expect("synth");
    json_result(
        &[
            "ingest",
            "llff",
            path_str(&p("data")),
            "-o",
            path_str(&p("s")),
        ],
        &p("s"),
    );

    // While it runs, the log is beside the (not yet existing) output and already has readings.
    let (out, live) = (p("t"), p("t.train-log.jsonl"));
    let mut child = Command::new(cocog_bin())
        .args([
            "train",
            path_str(&p("s")),
            "-o",
            path_str(&out),
            "--method",
            "3dgs",
        ])
        .args([
            "--iterations",
            "60",
            "--eval-every",
            "25",
            "--progress-every",
            "0.05",
        ])
        .env_remove("COCOG_PLUGIN_PATH")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn cocog train");
    let started = Instant::now();
    let mut seen_live = None;
    while child.try_wait().expect("try_wait").is_none() {
        let text = std::fs::read_to_string(&live).unwrap_or_default();
        if !out.exists() && text.lines().any(|l| l.contains("\"loss\":")) {
            seen_live = Some(text);
        }
        assert!(started.elapsed() < Duration::from_secs(300), "train hangs");
        std::thread::sleep(Duration::from_millis(5));
    }
    let done = child.wait_with_output().expect("wait");
    let err = String::from_utf8_lossy(&done.stderr).into_owned();
    assert!(done.status.success(), "{err}");
    let seen = seen_live.unwrap_or_else(|| panic!("never saw the live log while training:\n{err}"));
    assert!(seen.starts_with("{\"start\""), "{seen}");
    assert!(
        err.contains(&format!("training log: {}", live.display())),
        "the user is told where the log is:\n{err}"
    );
    // No terminal here: lines paced by time stand in for the progress bar.
    let paced = err
        .lines()
        .filter(|l| l.starts_with("train: ") && l.contains("/60 ("))
        .count();
    assert!(paced >= 2, "{paced} progress lines:\n{err}");

    // On success the log is in the output, whole, and the live one is gone.
    assert!(!live.exists(), "the live log outlived the run");
    let log = std::fs::read_to_string(out.join("train-log.jsonl")).expect("final log");
    assert!(
        log.starts_with(&seen),
        "lines seen while training were lost"
    );
    let all = records(&log);
    let evals: Vec<&Value> = all.iter().filter_map(|r| r.get("eval")).collect();
    let at: Vec<u64> = evals
        .iter()
        .filter_map(|e| e["iteration"].as_u64())
        .collect();
    assert_eq!(at, [25, 50, 60], "{log}");
    assert!(err.contains("iteration 50: test views PSNR"), "{err}");

    // The test PSNR logged at the end is what `cocog eval` measures on the output.
    let scores = json_result(
        &[
            "eval",
            path_str(&out),
            "-o",
            path_str(&p("m.json")),
            "--lpips",
            "off",
        ],
        &p("m.json"),
    );
    let (logged, measured) = (evals[2]["psnr"].as_f64(), scores["mean"]["psnr"].as_f64());
    let (logged, measured) = (logged.expect("psnr"), measured.expect("eval psnr"));
    assert!(
        (logged - measured).abs() < 1e-3,
        "log {logged} vs eval {measured}"
    );
}

#[test]
fn json_results_name_the_output() {
    let work = tempfile::tempdir().expect("tempdir");
    let p = |name: &str| work.path().join(name);
    write_defocus_dataset(&p("data"), &SynthConfig::tiny(5)).expect("synth");
    let (data, s, t) = (p("data"), p("s"), p("t"));
    json_result(&["ingest", "llff", path_str(&data), "-o", path_str(&s)], &s);
    json_result(
        &[
            "densify",
            path_str(&s),
            "-o",
            path_str(&p("d")),
            "--points",
            "50",
        ],
        &p("d"),
    );
    let trained = json_result(
        &[
            "train",
            path_str(&s),
            "-o",
            path_str(&t),
            "--iterations",
            "10",
            "--method",
            "3dgs",
        ],
        &t,
    );
    assert_eq!(trained["iterations"], 10, "{trained}");
    let ply = p("t.ply");
    json_result(
        &[
            "export",
            path_str(&t),
            "--format",
            "ply",
            "-o",
            path_str(&ply),
        ],
        &ply,
    );
    json_result(&["render", path_str(&t), "-o", path_str(&p("r"))], &p("r"));
    json_result(&["prune", path_str(&t), "-o", path_str(&p("pr"))], &p("pr"));
    json_result(
        &[
            "convert",
            path_str(&s),
            "--to",
            "nerf",
            "-o",
            path_str(&p("n")),
        ],
        &p("n"),
    );
}
