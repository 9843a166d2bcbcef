//! `--force` replaces only outputs cocog wrote: never a folder of the user's files, the
//! current directory or a parent of the input, and a refused run touches nothing.

use std::path::Path;
use std::process::Command;

use cocog_tests::{
    cdylib, cocog, cocog_bin, listing, path_str, scene_with_gaussians, stderr, write_tiny_scene,
};

fn recenter_args<'a>(input: &'a Path, output: &'a str, lib: &'a Path) -> Vec<&'a str> {
    vec![
        "stage",
        "recenter",
        path_str(input),
        "-o",
        output,
        "--plugin-path",
        path_str(lib),
        "--force",
    ]
}

#[test]
fn force_refuses_what_cocog_did_not_write_and_replaces_what_it_did() {
    let lib = cdylib("cocog-plugin-recenter");
    let work = tempfile::tempdir().expect("tempdir");
    let input = work.path().join("scene");
    write_tiny_scene(&input, 4, [0.0; 3], 1.0);

    // A folder of the user's files.
    let mine = work.path().join("mine");
    std::fs::create_dir(&mine).unwrap();
    std::fs::write(mine.join("notes.txt"), b"keep me").unwrap();
    let out = cocog(&recenter_args(&input, path_str(&mine), &lib));
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("will not replace") && err.contains("did not write"),
        "{err}"
    );
    assert_eq!(std::fs::read(mine.join("notes.txt")).unwrap(), b"keep me");

    // The parent of the input.
    let out = cocog(&recenter_args(&input, path_str(work.path()), &lib));
    assert!(stderr(&out).contains("input"), "{}", stderr(&out));
    assert!(input.join("scene.json").exists());

    // What cocog wrote is replaced, twice over.
    let made = work.path().join("made");
    for _ in 0..2 {
        let out = cocog(&recenter_args(&input, path_str(&made), &lib));
        assert!(out.status.success(), "{}", stderr(&out));
    }
    assert!(made.join("scene.json").exists());

    // The current directory, even one cocog wrote: `-o .` from inside it.
    let out = Command::new(cocog_bin())
        .args(recenter_args(&input, ".", &lib))
        .current_dir(&made)
        .env_remove("COCOG_PLUGIN_PATH")
        .output()
        .unwrap();
    assert!(
        stderr(&out).contains("current directory"),
        "{}",
        stderr(&out)
    );
    assert!(made.join("scene.json").exists());
    let mut names = listing(work.path());
    names.sort();
    assert_eq!(names, vec!["made", "mine", "scene"]);
}

#[test]
fn export_force_replaces_a_ply_but_not_a_folder_or_a_foreign_file() {
    let work = tempfile::tempdir().expect("tempdir");
    let input = work.path().join("scene");
    scene_with_gaussians(&input);
    let export = |output: &Path| {
        cocog(&[
            "export",
            path_str(&input),
            "--format",
            "ply",
            "-o",
            path_str(output),
            "--force",
        ])
    };

    // `-o exports/` where exports holds the user's files: the table's first row.
    let exports = work.path().join("exports");
    std::fs::create_dir(&exports).unwrap();
    std::fs::write(exports.join("old.glb"), b"glTF keep").unwrap();
    let out = export(&exports);
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    assert!(stderr(&out).contains("is a folder"), "{}", stderr(&out));
    assert_eq!(listing(&exports), vec!["old.glb"]);

    // A file that is not something cocog writes.
    let notes = work.path().join("notes.ply");
    std::fs::write(&notes, b"my notes, misnamed").unwrap();
    let out = export(&notes);
    assert!(
        stderr(&out).contains("format cocog writes"),
        "{}",
        stderr(&out)
    );
    assert_eq!(std::fs::read(&notes).unwrap(), b"my notes, misnamed");

    // A PLY cocog exported earlier is replaced.
    let ply = work.path().join("scene.ply");
    for _ in 0..2 {
        let out = export(&ply);
        assert!(out.status.success(), "{}", stderr(&out));
    }
    assert!(std::fs::read(&ply).unwrap().starts_with(b"ply\n"));
}
