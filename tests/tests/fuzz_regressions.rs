//! Inputs that once broke a reader under `fuzz/run`, kept in `fuzz/regressions/<target>/` and
//! replayed by every `cargo test`: each must be read or refused with an error, never panic,
//! abort or hang. A new finding needs no code here: save the file in its target's folder.

use std::path::{Path, PathBuf};
use std::sync::mpsc;
use std::time::Duration;

use cocog_formats::colmap::{Camera, CameraModel, Image, Model, Point2D, Point3D, TrackElement};

/// The saved inputs of fuzz target `target`, sorted; none if the folder does not exist.
fn cases(target: &str) -> Vec<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../fuzz/regressions")
        .join(target);
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .map(|d| d.map(|e| e.expect("list regressions").path()).collect())
        .unwrap_or_default();
    files.retain(|p| p.is_file());
    files.sort();
    files
}

/// Runs `read` on every saved input of `target`, each within 30 s (the fuzzer's hang limit is
/// 10 s; the margin is for slow debug builds). A panic fails the test naming the input.
fn replay(target: &str, read: fn(&[u8])) {
    for case in cases(target) {
        let data = std::fs::read(&case).expect("read regression input");
        let (done, finished) = mpsc::channel();
        let name = case.display().to_string();
        let worker = std::thread::spawn(move || {
            read(&data);
            let _ = done.send(());
        });
        match finished.recv_timeout(Duration::from_secs(30)) {
            Ok(()) => worker.join().expect("reader thread"),
            Err(mpsc::RecvTimeoutError::Timeout) => panic!("{name}: the reader hangs"),
            Err(mpsc::RecvTimeoutError::Disconnected) => {
                panic!("{name}: the reader panicked (message above)")
            }
        }
    }
}

/// Writes `data` as `name` in a fresh folder and returns the folder and the file.
fn staged(name: &str, data: &[u8]) -> (tempfile::TempDir, PathBuf) {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join(name);
    std::fs::write(&path, data).expect("write input");
    (dir, path)
}

#[test]
fn ply_regressions() {
    replay("ply", |data| {
        let (_dir, path) = staged("input.ply", data);
        let _ = cocog_formats::ply::read_points(&path);
        let _ = cocog_formats::ply::read_splats(&path);
    });
}

#[test]
fn glb_regressions() {
    assert!(!cases("glb").is_empty(), "fuzz/regressions/glb is missing");
    replay("glb", |data| {
        let (_dir, path) = staged("input.glb", data);
        let _ = cocog_formats::glb::read_glb(&path);
    });
}

#[test]
fn npy_regressions() {
    replay("npy", |data| {
        let (_dir, path) = staged("poses_bounds.npy", data);
        let _ = cocog_formats::llff::read_poses_bounds(&path);
    });
}

/// As fuzz/src/lib.rs: a `colmap_bin` input is a selector byte (which of the three files, mod
/// 3) followed by that file; the other two files are those of a small valid model.
#[test]
fn colmap_bin_regressions() {
    replay("colmap_bin", |data| {
        let Some((&which, file)) = data.split_first() else {
            return;
        };
        let dir = tempfile::tempdir().expect("temp dir");
        cocog_formats::colmap::write_bin(&small_model(), dir.path()).expect("write model");
        let name = ["cameras.bin", "images.bin", "points3D.bin"][usize::from(which) % 3];
        std::fs::write(dir.path().join(name), file).expect("write input");
        let _ = cocog_formats::colmap::read_model(dir.path());
    });
}

fn small_model() -> Model {
    Model {
        cameras: vec![Camera {
            id: 1,
            model: CameraModel::Pinhole,
            width: 32,
            height: 32,
            params: vec![30.0, 30.0, 16.0, 16.0],
        }],
        images: vec![Image {
            id: 3,
            qvec: [1.0, 0.0, 0.0, 0.0],
            tvec: [0.0, 0.0, 1.0],
            camera_id: 1,
            name: "a.png".into(),
            points2d: vec![Point2D {
                xy: [1.0, 2.0],
                point3d_id: Some(7),
            }],
        }],
        points: vec![Point3D {
            id: 7,
            xyz: [0.1, 0.2, 3.0],
            rgb: [1, 2, 3],
            error: 0.5,
            track: vec![TrackElement {
                image_id: 3,
                point2d_idx: 0,
            }],
        }],
    }
}

#[test]
fn scene_json_regressions() {
    replay("scene_json", |data| {
        let (dir, _) = staged(cocog_pipeline::scene::MANIFEST, data);
        let _ = cocog_pipeline::Scene::load(dir.path());
    });
}

#[test]
fn checkpoint_regressions() {
    replay("checkpoint", |data| {
        let (_dir, path) = staged(cocog_train::CHECKPOINT_FILE, data);
        let _ = cocog_train::TrainState::load(&path);
    });
}
