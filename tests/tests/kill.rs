//! SIGKILL in the middle of training — of `cocog train` and of a `cocog run` pipeline —
//! then resume: at most one checkpoint interval is lost, the log keeps every earlier line,
//! nothing stale is left beside the output, and the result matches an uninterrupted run.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use cocog_synth::{SynthConfig, write_defocus_dataset};
use cocog_tests::{cocog, cocog_bin, listing, path_str, stderr, stdout};
use serde_json::Value;

const ITERATIONS: &str = "160";
const EVERY: u64 = 20;

fn ingested(root: &Path) -> PathBuf {
    let data = root.join("data");
    write_defocus_dataset(&data, &SynthConfig::tiny(4)).expect("synth");
    let scene = root.join("scene");
    let out = cocog(&["ingest", "llff", path_str(&data), "-o", path_str(&scene)]);
    assert!(out.status.success(), "{}", stderr(&out));
    scene
}

fn spawn(args: &[&str]) -> Child {
    Command::new(cocog_bin())
        .args(args)
        .env_remove("COCOG_PLUGIN_PATH")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("spawn cocog")
}

/// Waits until `ckpt` holds a checkpoint past the first, then SIGKILLs the process.
fn kill_after_checkpoints(mut child: Child, ckpt: &Path) {
    let state = ckpt.join("state.safetensors");
    let started = Instant::now();
    let mut first = None;
    loop {
        if let Some(status) = child.try_wait().expect("try_wait") {
            panic!("training ended ({status}) before it could be killed");
        }
        assert!(
            started.elapsed() < Duration::from_secs(600),
            "no checkpoint appeared"
        );
        let modified = std::fs::metadata(&state).and_then(|m| m.modified()).ok();
        match (first, modified) {
            (None, Some(t)) => first = Some(t),
            (Some(a), Some(b)) if b != a => break,
            _ => {}
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    // Some way past that checkpoint, as a real kill would be.
    std::thread::sleep(Duration::from_millis(300));
    child.kill().expect("SIGKILL");
    child.wait().expect("reap");
}

/// The log's training readings, by iteration.
fn logged_iterations(log: &str) -> Vec<u64> {
    log.lines()
        .filter_map(|l| serde_json::from_str::<Value>(l).ok())
        .filter_map(|v| v["iteration"].as_u64())
        .collect()
}

/// The furthest iteration the killed run logged (OUTPUT.train-log.jsonl beside its output,
/// written line by line), and the log.
fn last_logged_iteration(parent: &Path, output_name: &str) -> (u64, String) {
    let path = parent.join(format!("{output_name}.train-log.jsonl"));
    let log = std::fs::read_to_string(&path).expect("the killed run's live log");
    let last = logged_iterations(&log).into_iter().max();
    let last = last.unwrap_or_else(|| panic!("the killed run logged no iteration:\n{log}"));
    (last, log)
}

/// The finished output's log begins with everything the killed run logged, then the resumed
/// run's `start` record and its readings up to the end.
fn assert_log_continues(output: &Path, killed_log: &str, from: u64) {
    let log = std::fs::read_to_string(output.join("train-log.jsonl")).expect("final log");
    assert!(log.starts_with(killed_log), "earlier lines lost:\n{log}");
    // A line the kill cut short was ended before the resumed run's first.
    let rest: Vec<Value> = log[killed_log.len()..]
        .lines()
        .filter(|l| !l.is_empty())
        .map(|l| serde_json::from_str(l).expect("JSON line"))
        .collect();
    assert_eq!(rest[0]["start"]["iteration"], from, "{log}");
    let last = logged_iterations(&log).into_iter().max();
    assert_eq!(last.map(|i| i.to_string()).as_deref(), Some(ITERATIONS));
}

fn test_psnr(scene: &Path) -> f64 {
    let out = cocog(&["eval", path_str(scene), "--json"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let v: Value = serde_json::from_str(&stdout(&out)).expect("eval JSON");
    v["mean"]["psnr"]
        .as_f64()
        .unwrap_or_else(|| panic!("no PSNR in {v}"))
}

fn train_args<'a>(scene: &'a Path, out: &'a Path) -> Vec<&'a str> {
    vec![
        "train",
        path_str(scene),
        "-o",
        path_str(out),
        "--iterations",
        ITERATIONS,
        // CoCoGaussian, the default, named: its lens model must resume exactly too.
        "--method",
        "cocog",
        "--compositor-channels",
        "8",
        "--checkpoint-every",
        "20",
        "--seed",
        "5",
    ]
}

#[test]
fn sigkilled_training_resumes_to_the_uninterrupted_result() {
    let work = tempfile::tempdir().expect("tempdir");
    let scene = ingested(work.path());
    let whole = work.path().join("whole");
    let out = cocog(&train_args(&scene, &whole));
    assert!(out.status.success(), "{}", stderr(&out));

    let killed = work.path().join("killed");
    let ckpt = work.path().join("killed.checkpoint");
    kill_after_checkpoints(spawn(&train_args(&scene, &killed)), &ckpt);
    let (reached, killed_log) = last_logged_iteration(work.path(), "killed");

    // A fresh run refuses to overwrite the checkpoint; resuming continues it.
    let out = cocog(&train_args(&scene, &killed));
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    assert!(stderr(&out).contains("--resume"), "{}", stderr(&out));
    let mut args = train_args(&scene, &killed);
    args.extend(["--resume", path_str(&ckpt), "--json"]);
    let out = cocog(&args);
    assert!(out.status.success(), "{}", stderr(&out));
    let summary: Value = serde_json::from_str(&stdout(&out)).expect("summary JSON");
    let from = summary["resumed_from"].as_u64().expect("resumed_from");
    assert!(
        from >= EVERY && from + EVERY >= reached,
        "resumed at {from}, killed past {reached}"
    );
    assert_eq!(summary["output"], path_str(&killed));
    assert_log_continues(&killed, &killed_log, from);

    let names = listing(work.path());
    assert_eq!(
        names,
        vec!["data", "killed", "scene", "whole"],
        "left behind"
    );
    let (a, b) = (test_psnr(&whole), test_psnr(&killed));
    eprintln!("killed past {reached}, resumed at {from}: {b:.4} dB vs uninterrupted {a:.4} dB");
    assert!(
        (a - b).abs() <= 0.2,
        "uninterrupted {a:.3} dB, killed and resumed {b:.3} dB"
    );
}

/// `root/p.toml`: ingest `root/data` (a tiny synthetic dataset, written here), then a 3dgs
/// training into `root/out` checkpointing every EVERY iterations, with `train` (TOML lines)
/// added to its table.
fn training_pipeline(root: &Path, train: &str) -> PathBuf {
    write_defocus_dataset(&root.join("data"), &SynthConfig::tiny(4)).expect("synth");
    let pipeline = root.join("p.toml");
    std::fs::write(
        &pipeline,
        format!(
            "[pipeline]\ninput = \"data\"\noutput = \"out\"\nstages = [\"ingest-llff\", \"train\"]\n\
             [train]\nmethod = \"3dgs\"\ncheckpoint_every = {EVERY}\n{train}\n"
        ),
    )
    .expect("write pipeline");
    pipeline
}

#[test]
fn a_sigkilled_pipeline_resumes_its_training_stage() {
    let work = tempfile::tempdir().expect("tempdir");
    let pipeline = training_pipeline(work.path(), &format!("iterations = {ITERATIONS}\nseed = 5"));
    // Training is the last stage, so its checkpoint sits beside the pipeline's output.
    let ckpt = work.path().join("out.checkpoint");
    kill_after_checkpoints(spawn(&["run", path_str(&pipeline)]), &ckpt);
    let (reached, killed_log) = last_logged_iteration(work.path(), "out");

    let out = cocog(&["run", path_str(&pipeline), "--resume", "--json"]);
    let err = stderr(&out);
    assert!(out.status.success(), "{err}");
    assert!(err.contains("ingest-llff: kept"), "{err}");
    assert!(err.contains("resuming from"), "{err}");
    let summary: Value = serde_json::from_str(&stdout(&out)).expect("summary JSON");
    let from = summary["stages"][1]["summary"]["resumed_from"]
        .as_u64()
        .unwrap_or_else(|| panic!("{summary}"));
    assert!(
        from >= EVERY && from + EVERY >= reached,
        "resumed at {from}, killed past {reached}"
    );
    assert_log_continues(&work.path().join("out"), &killed_log, from);
    assert_eq!(
        listing(work.path()),
        vec!["data", "out", "out.stages", "p.toml"]
    );
    assert_eq!(
        listing(&work.path().join("out.stages")),
        vec!["01-ingest-llff"]
    );
    assert!(test_psnr(&work.path().join("out")) > 15.0);
}

#[test]
fn an_interrupted_pipeline_says_how_to_continue_it() {
    let work = tempfile::tempdir().expect("tempdir");
    let pipeline = training_pipeline(work.path(), "iterations = 5000");
    // Far more iterations than it will run: the interrupt must find it still training.
    let child = Command::new(cocog_bin())
        .args(["run", path_str(&pipeline)])
        .env_remove("COCOG_PLUGIN_PATH")
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn cocog");
    let state = work.path().join("out.checkpoint/state.safetensors");
    let started = Instant::now();
    while !state.is_file() {
        assert!(
            started.elapsed() < Duration::from_secs(600),
            "no checkpoint appeared"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    let pid = child.id().to_string();
    let sent = Command::new("kill").args(["-INT", &pid]).status();
    assert!(sent.expect("kill -INT").success());
    let out = child.wait_with_output().expect("wait");
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(130), "{err}");
    let said = format!("cocog run {} --resume", pipeline.display());
    assert!(err.contains(&said), "{err}");
}
