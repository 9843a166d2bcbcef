//! Bad numbers and bad output paths from the command line: a clear message naming the
//! option or the user's path, before any work, and nothing left behind.

use cocog_tests::{cocog, listing, path_str, scene_with_gaussians, stderr, write_tiny_scene};

#[test]
fn non_finite_and_oversized_numbers_are_refused_by_name() {
    let work = tempfile::tempdir().expect("tempdir");
    let scene = work.path().join("scene");
    scene_with_gaussians(&scene);
    let out_dir = work.path().join("out");
    let o = path_str(&out_dir);
    let s = path_str(&scene);
    let cases: [(&[&str], &str); 5] = [
        (&["prune", s, "-o", o, "--threshold", "nan"], "--threshold"),
        (&["prune", s, "-o", o, "--range", "inf"], "--range"),
        (
            &["densify", s, "-o", o, "--max-distance", "NaN"],
            "--max-distance",
        ),
        (
            &["densify", s, "-o", o, "--points", "1000000000000"],
            "option 'points': expected a number from 0 to 100000000",
        ),
        (
            &["stage", "prune", s, "-o", o, "--set", "threshold=nan"],
            "'threshold'",
        ),
    ];
    for (args, wanted) in cases {
        let out = cocog(args);
        let err = stderr(&out);
        assert!(matches!(out.status.code(), Some(1 | 2)), "{args:?}: {err}");
        assert!(err.contains(wanted), "{args:?}: {err}");
        assert!(!err.contains("Some(") && !err.contains("Os {"), "{err}");
        assert_eq!(listing(work.path()), vec!["scene"], "{args:?} left files");
    }
}

#[test]
fn output_paths_that_cannot_work_name_the_users_path() {
    let work = tempfile::tempdir().expect("tempdir");
    let scene = work.path().join("scene");
    scene_with_gaussians(&scene);
    let s = path_str(&scene);

    // `-o newdir/` for a stage that writes one file: refused before it writes anything.
    let newdir = format!("{}/", work.path().join("newdir").display());
    let out = cocog(&["export", s, "--format", "ply", "-o", &newdir]);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("names a folder") && !err.contains("wrote"),
        "{err}"
    );

    // An output under a file: the message names the user's folder, not a temp path.
    let file = work.path().join("a-file");
    std::fs::write(&file, b"x").expect("write");
    let inside = file.join("out");
    let out = cocog(&["densify", s, "-o", path_str(&inside)]);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("a-file") && !err.contains("cocog-tmp"),
        "{err}"
    );
    assert_eq!(listing(work.path()), vec!["a-file", "scene"]);
}

#[cfg(target_os = "linux")]
#[test]
fn a_killed_runs_temp_folder_is_cleaned_by_the_next_run() {
    let work = tempfile::tempdir().expect("tempdir");
    let scene = work.path().join("scene");
    write_tiny_scene(&scene, 4, [0.0; 3], 1.0);
    // What SIGKILL leaves: a staging folder of a process that no longer exists.
    let stale = work.path().join(".dense.cocog-tmp-4194305-0");
    std::fs::create_dir(&stale).expect("mkdir");
    std::fs::write(stale.join("points.ply"), b"half").expect("write");
    let out = cocog(&[
        "densify",
        path_str(&scene),
        "-o",
        path_str(&work.path().join("dense")),
        "--points",
        "100",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert_eq!(listing(work.path()), vec!["dense", "scene"]);
}

#[test]
fn image_paths_outside_the_dataset_need_allow_outside() {
    let work = tempfile::tempdir().expect("tempdir");
    let data = work.path().join("data");
    cocog_synth::write_defocus_dataset(&data, &cocog_synth::SynthConfig::tiny(2)).expect("synth");
    let nerf = work.path().join("nerf");
    std::fs::create_dir(&nerf).expect("mkdir");
    let frames: Vec<_> = (0..4)
        .map(|i| {
            serde_json::json!({
                "file_path": format!("../data/images/{i:03}.png"),
                "transform_matrix": [[1, 0, 0, 0.1 * f64::from(i)], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]],
            })
        })
        .collect();
    let transforms = serde_json::json!({ "camera_angle_x": 0.8, "frames": frames });
    std::fs::write(nerf.join("transforms.json"), transforms.to_string()).expect("write");
    let scene = work.path().join("scene");
    let args = ["ingest", "nerf", path_str(&nerf), "-o", path_str(&scene)];
    let out = cocog(&args);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("transforms.json") && err.contains("../data/images/000.png"),
        "{err}"
    );
    assert!(err.contains("--allow-outside"), "{err}");
    assert!(!scene.exists());
    let mut allowed = args.to_vec();
    allowed.push("--allow-outside");
    let out = cocog(&allowed);
    assert!(out.status.success(), "{}", stderr(&out));
}
