//! GPU commands on a headless machine (no XDG_RUNTIME_DIR: ssh, containers, CI) succeed without
//! a single `error:` line on stderr: a false alarm there reads as a failure.

use std::path::Path;
use std::process::{Command, Output};

use cocog_synth::{SynthConfig, write_defocus_dataset};
use cocog_tests::{cocog, cocog_bin, path_str, stderr};

/// `cocog ARGS` in a headless environment: no runtime dir, no display, nothing asked of
/// Mesa's device-select layer.
fn headless(args: &[&str]) -> Output {
    Command::new(cocog_bin())
        .args(args)
        .env_remove("COCOG_PLUGIN_PATH")
        .env_remove("XDG_RUNTIME_DIR")
        .env_remove("WAYLAND_DISPLAY")
        .env_remove("DISPLAY")
        .env_remove("NODEVICE_SELECT")
        .env_remove("MESA_VK_DEVICE_SELECT")
        .output()
        .expect("run cocog")
}

fn assert_quiet_success(what: &str, out: &Output) {
    let err = stderr(out);
    assert!(out.status.success(), "{what} failed:\n{err}");
    let alarms: Vec<&str> = err.lines().filter(|l| l.contains("error:")).collect();
    assert!(
        alarms.is_empty(),
        "{what} succeeded but stderr says {alarms:?}:\n{err}"
    );
}

#[test]
fn gpu_commands_print_no_error_without_a_runtime_dir() {
    let work = tempfile::tempdir().expect("tempdir");
    let [data, scene, trained, renders, metrics] =
        ["data", "s", "t", "r", "metrics.json"].map(|n| work.path().join(n));
    let [data, scene, trained, renders, metrics_s] =
        [&data, &scene, &trained, &renders, &metrics].map(|p| path_str(p));
    write_defocus_dataset(Path::new(data), &SynthConfig::tiny(3)).expect("synth");
    let out = cocog(&["ingest", "llff", data, "-o", scene]);
    assert!(out.status.success(), "{}", stderr(&out));

    let train = [
        "train",
        scene,
        "-o",
        trained,
        "--iterations",
        "20",
        "--method",
        "3dgs",
    ];
    assert_quiet_success("train", &headless(&train));
    assert_quiet_success("render", &headless(&["render", trained, "-o", renders]));
    let eval = ["eval", trained, "-o", metrics_s, "--lpips", "off"];
    assert_quiet_success("eval", &headless(&eval));
    let bench = ["bench", scene, "--iterations", "3", "--warmup", "1"];
    assert_quiet_success("bench", &headless(&bench));
    assert!(metrics.is_file());
}
