//! Bad input gets a one-line error naming the path and cause, and leaves nothing behind.

use std::path::Path;

use cocog_tests::{cdylib, cocog, listing, path_str, stderr, write_tiny_scene};

fn recenter(input: &Path, output: &Path, extra: &[&str]) -> std::process::Output {
    let lib = cdylib("cocog-plugin-recenter");
    let mut args = vec![
        "stage",
        "recenter",
        path_str(input),
        "-o",
        path_str(output),
        "--plugin-path",
        path_str(&lib),
    ];
    args.extend_from_slice(extra);
    cocog(&args)
}

fn assert_one_line_error(out: &std::process::Output, needles: &[&str]) {
    assert_error_exit(out, 1, needles);
}

/// One `error:` line holding every needle, and exit status `code`.
fn assert_error_exit(out: &std::process::Output, code: i32, needles: &[&str]) {
    let err = stderr(out);
    assert_eq!(out.status.code(), Some(code), "{err}");
    let errors: Vec<&str> = err.lines().filter(|l| l.starts_with("error:")).collect();
    assert_eq!(errors.len(), 1, "{err}");
    for n in needles {
        assert!(errors[0].contains(n), "{n:?} not in {err}");
    }
}

#[test]
fn missing_input_directory() {
    let work = tempfile::tempdir().expect("tempdir");
    let out = recenter(&work.path().join("nope"), &work.path().join("out"), &[]);
    assert_one_line_error(&out, &["nope", "input does not exist"]);
    assert!(listing(work.path()).is_empty());
}

#[test]
fn missing_manifest() {
    let work = tempfile::tempdir().expect("tempdir");
    let input = work.path().join("empty");
    std::fs::create_dir(&input).expect("mkdir");
    let out = recenter(&input, &work.path().join("out"), &[]);
    assert_one_line_error(&out, &["empty/scene.json", "No such file"]);
    assert_eq!(listing(work.path()), vec!["empty"]);
}

#[test]
fn corrupt_manifest() {
    let work = tempfile::tempdir().expect("tempdir");
    let input = work.path().join("scene");
    write_tiny_scene(&input, 4, [0.0; 3], 1.0);
    std::fs::write(
        input.join("scene.json"),
        "{\"format\": \"cocog.scene\", \"vers",
    )
    .expect("write");
    let out = recenter(&input, &work.path().join("out"), &[]);
    assert_one_line_error(
        &out,
        &["scene/scene.json", "not a valid scene manifest", "line 1"],
    );
    assert_eq!(listing(work.path()), vec!["scene"]);
}

#[test]
fn a_manifest_field_of_the_wrong_shape_is_located() {
    let work = tempfile::tempdir().expect("tempdir");
    let input = work.path().join("scene");
    write_tiny_scene(&input, 4, [0.0; 3], 1.0);
    let path = input.join("scene.json");
    let mut doc: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&path).expect("read")).expect("json");
    doc["views"][1]["world_from_camera"]
        .as_array_mut()
        .expect("pose rows")
        .pop();
    std::fs::write(&path, serde_json::to_string_pretty(&doc).expect("json")).expect("write");
    let out = recenter(&input, &work.path().join("out"), &[]);
    // Pretty-printed, the line points at the view; the bare serde message said nothing of where.
    assert_one_line_error(&out, &["scene/scene.json", "invalid length 3", "line"]);
}

#[test]
fn unknown_major_version() {
    let work = tempfile::tempdir().expect("tempdir");
    let input = work.path().join("scene");
    write_tiny_scene(&input, 4, [0.0; 3], 1.0);
    let path = input.join("scene.json");
    let text = std::fs::read_to_string(&path).expect("read");
    std::fs::write(&path, text.replace("\"1.0\"", "\"7.2\"")).expect("write");
    let out = recenter(&input, &work.path().join("out"), &[]);
    assert_one_line_error(&out, &["scene.json", "version 7.2", "reads 1.x"]);
}

#[test]
fn output_exists_is_refused_unless_forced() {
    let work = tempfile::tempdir().expect("tempdir");
    let input = work.path().join("scene");
    write_tiny_scene(&input, 4, [1.0, 2.0, 3.0], 1.0);
    let output = work.path().join("out");
    std::fs::create_dir(&output).expect("mkdir");
    std::fs::write(output.join("keep.txt"), "precious").expect("write");
    let out = recenter(&input, &output, &[]);
    assert_one_line_error(&out, &["out", "already exists", "--force"]);
    assert!(
        output.join("keep.txt").exists(),
        "refused run must not touch the output"
    );

    // A folder of the user's files is not cocog's to replace, even with --force.
    let out = recenter(&input, &output, &["--force"]);
    assert_one_line_error(&out, &["out", "will not replace", "did not write"]);
    assert_eq!(
        std::fs::read_to_string(output.join("keep.txt")).unwrap(),
        "precious"
    );

    // An output cocog wrote is replaced.
    let made = work.path().join("made");
    for extra in [&[][..], &["--force"][..]] {
        let out = recenter(&input, &made, extra);
        assert!(out.status.success(), "{}", stderr(&out));
    }
    assert!(made.join("scene.json").exists());
    let mut names = listing(work.path());
    names.sort();
    assert_eq!(names, vec!["made", "out", "scene"]);
}

#[test]
fn bad_option_values_are_named() {
    let work = tempfile::tempdir().expect("tempdir");
    let input = work.path().join("scene");
    write_tiny_scene(&input, 4, [0.0; 3], 1.0);
    let out = recenter(&input, &work.path().join("o"), &["--set", "radius=\"big\""]);
    // A bad value or an unknown option is a usage error, as clap's own are.
    assert_error_exit(&out, 2, &["option 'radius'", "expected float"]);
    let out = recenter(&input, &work.path().join("o"), &["--set", "raduis=2"]);
    assert_error_exit(&out, 2, &["no option 'raduis'", "radius"]);
    // One the stage itself refuses, past the option table's checks.
    let s = input.to_str().expect("utf-8");
    let o = work.path().join("t");
    let out = cocog(&[
        "train",
        s,
        "-o",
        o.to_str().expect("utf-8"),
        "--background",
        "purple",
    ]);
    assert_error_exit(&out, 2, &["option 'background'", "purple"]);
    assert_eq!(listing(work.path()), vec!["scene"]);
}

#[test]
fn unknown_stage_exits_3_and_lists_the_stages() {
    let out = cocog(&["stage", "no-such-stage", "a", "-o", "b"]);
    assert_eq!(out.status.code(), Some(3), "{}", stderr(&out));
    assert!(stderr(&out).contains("no-such-stage"), "{}", stderr(&out));
    assert!(stderr(&out).contains("eval-scene"), "{}", stderr(&out));
}

#[test]
fn rendering_an_untrained_scene_names_the_missing_field() {
    let work = tempfile::tempdir().expect("tempdir");
    let input = work.path().join("scene");
    write_tiny_scene(&input, 4, [0.0; 3], 1.0);
    let out = cocog(&[
        "render",
        path_str(&input),
        "-o",
        path_str(&work.path().join("r")),
    ]);
    assert_one_line_error(&out, &["scene.json", "`gaussians`", "cocog train"]);
    assert_eq!(listing(work.path()), vec!["scene"]);
}

#[test]
fn usage_errors_exit_2() {
    // --split and --downscale pick a scene's views; a --pred folder has none.
    let out = cocog(&["eval", "--pred", "a", "--gt", "b", "--split", "train"]);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert!(stderr(&out).contains("--split"), "{}", stderr(&out));
    let out = cocog(&["ingest", "llff"]);
    assert_eq!(out.status.code(), Some(2));
    let out = cocog(&["stage", "recenter", "a", "-o", "b", "--set", "novalue"]);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
}
