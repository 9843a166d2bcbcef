//! The ingest stages on the bench scenes: all three layouts give the same scene; bad datasets
//! fail with a message naming the file and what is wrong.

use std::path::{Path, PathBuf};

use cocog_pipeline::{NullContext, Options, Scene, Split, Stage, StageError, StageRequest};
use serde_json::{Value, json};

fn dev_scenes() -> Vec<PathBuf> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/bench/defocus-dev");
    let scenes: Vec<PathBuf> = ["dev-table", "dev-shelf"]
        .iter()
        .map(|s| root.join(s))
        .filter(|p| p.is_dir())
        .collect();
    if scenes.is_empty() {
        eprintln!("SKIP: bench data not found at {}", root.display());
    }
    scenes
}

fn run(
    stage: &str,
    input: &Path,
    options: Value,
) -> Result<(tempfile::TempDir, Value), StageError> {
    let stage: Box<dyn Stage> = cocog_ingest::stages()
        .into_iter()
        .find(|s| s.info().name == stage)
        .unwrap();
    let info = stage.info();
    let options = Options::validate(&info.name, &info.options, options.as_object().unwrap())?;
    let tmp = tempfile::tempdir().unwrap();
    let output = tmp.path().join("out");
    std::fs::create_dir(&output).unwrap();
    let summary = stage.run(
        &StageRequest {
            input: input.to_path_buf(),
            output,
            options,
        },
        &NullContext,
    )?;
    Ok((tmp, summary))
}

fn scene_of(tmp: &tempfile::TempDir) -> Scene {
    Scene::load(&tmp.path().join("out")).unwrap()
}

#[test]
fn colmap_llff_and_nerf_give_the_same_scene() {
    for dataset in dev_scenes() {
        let (c_dir, c_sum) = run("ingest-colmap", &dataset, json!({})).unwrap();
        let (l_dir, _) = run("ingest-llff", &dataset, json!({})).unwrap();
        let (n_dir, n_sum) = run("ingest-nerf", &dataset, json!({})).unwrap();
        assert_eq!(c_sum["split"], "hold=8");
        assert_eq!(n_sum["split"], "dataset");
        let (c, l, n) = (scene_of(&c_dir), scene_of(&l_dir), scene_of(&n_dir));
        for other in [&l, &n] {
            assert_eq!(other.views.len(), 24);
            assert_eq!(other.cameras.len(), 1);
            let (a, b) = (&c.cameras[0], &other.cameras[0]);
            assert_eq!((a.width, a.height), (b.width, b.height));
            for (x, y) in [(a.fx, b.fx), (a.fy, b.fy), (a.cx, b.cx), (a.cy, b.cy)] {
                assert!((x - y).abs() < 1e-9, "{x} vs {y}");
            }
            for (va, vb) in c.views.iter().zip(&other.views) {
                assert_eq!(
                    (&va.name, va.split, &va.image),
                    (&vb.name, vb.split, &vb.image)
                );
                let d = va
                    .world_from_camera
                    .iter()
                    .flatten()
                    .zip(vb.world_from_camera.iter().flatten())
                    .map(|(x, y)| (x - y).abs())
                    .fold(0.0, f64::max);
                assert!(d < 1e-5, "{}: poses differ by {d}", va.name);
            }
        }
        let test: Vec<&str> = c.views_in(Split::Test).map(|v| v.name.as_str()).collect();
        assert_eq!(test, ["000.png", "008.png", "016.png"]);
        // COLMAP and LLFF carry the model's points; the scene is +z up in the world (Blender).
        assert_eq!(c.points.as_deref(), Some("points.ply"));
        let pts = cocog_formats::ply::read_points(&c_dir.path().join("out/points.ply")).unwrap();
        assert!(pts.len() > 1000);
        assert!(l.points.is_some() && n.points.is_some());
        // transforms.json carries no points: the random fallback fills the cube INRIA uses.
        let fallback =
            cocog_formats::ply::read_points(&n_dir.path().join("out/points.ply")).unwrap();
        assert_eq!(fallback.len(), 100_000);
        assert_eq!(n_sum["points_source"], "random fallback");
        assert_eq!(c_sum["points_source"], "dataset");
        let up = c.up.unwrap();
        assert!(up[2] > 0.9, "{up:?}");
        assert!(
            n.views[3]
                .depth
                .as_deref()
                .unwrap()
                .ends_with("depth/003.exr")
        );
        let (lb, cb) = (l.bounds.unwrap(), c.bounds.unwrap());
        assert!(
            cb.near > 0.5 * lb.near
                && cb.near < 1.5 * lb.near
                && (cb.far - lb.far).abs() < 0.3 * lb.far,
            "{cb:?} vs {lb:?}"
        );
    }
}

#[test]
fn downscale_and_hold_options() {
    let Some(dataset) = dev_scenes().into_iter().next() else {
        return;
    };
    let (dir, sum) = run(
        "ingest-colmap",
        &dataset,
        json!({"downscale": 2, "hold": 5, "model": 0}),
    )
    .unwrap();
    assert_eq!(sum["split"], "hold=5");
    let s = scene_of(&dir);
    let cam = &s.cameras[0];
    assert_eq!((cam.width, cam.height), (200, 150));
    assert!((cam.fx - 388.888_888_888_888_86 / 2.0).abs() < 1e-9 && (cam.cx - 100.0).abs() < 1e-12);
    assert_eq!(s.views[1].image, "images/001.png");
    let img = image_size(&dir.path().join("out/images/001.png"));
    assert_eq!(img, (200, 150));
    assert_eq!(s.views.iter().filter(|v| v.split == Split::Test).count(), 5);
    let err = run("ingest-colmap", &dataset, json!({"model": 3}))
        .unwrap_err()
        .to_string();
    assert!(err.contains("sparse/3"), "{err}");
    let err = run("ingest-llff", &dataset, json!({"downscale": 0}))
        .unwrap_err()
        .to_string();
    assert!(err.contains("downscale"), "{err}");
}

fn image_size(p: &Path) -> (u32, u32) {
    cocog_formats::images::image_size(p).unwrap()
}

/// A writable copy of a bench scene without the large folders we do not need.
fn copy_scene(src: &Path) -> tempfile::TempDir {
    let tmp = tempfile::tempdir().unwrap();
    for sub in ["images", "sparse/0"] {
        std::fs::create_dir_all(tmp.path().join(sub)).unwrap();
        for e in std::fs::read_dir(src.join(sub)).unwrap() {
            let p = e.unwrap().path();
            std::fs::copy(&p, tmp.path().join(sub).join(p.file_name().unwrap())).unwrap();
        }
    }
    for f in ["poses_bounds.npy", "transforms.json", "hold=8"] {
        std::fs::copy(src.join(f), tmp.path().join(f)).unwrap();
    }
    tmp
}

#[test]
fn bad_datasets_fail_clearly() {
    let Some(dataset) = dev_scenes().into_iter().next() else {
        return;
    };
    let copy = copy_scene(&dataset);
    let d = copy.path();
    std::fs::remove_file(d.join("images/005.png")).unwrap();
    for stage in ["ingest-colmap", "ingest-nerf"] {
        let err = run(stage, d, json!({})).unwrap_err().to_string();
        assert!(
            err.contains("005.png") && err.contains("does not exist"),
            "{stage}: {err}"
        );
    }
    let err = run("ingest-llff", d, json!({})).unwrap_err().to_string();
    assert!(
        err.contains("24 rows") && err.contains("23 images"),
        "{err}"
    );

    image::RgbImage::new(40, 30)
        .save(d.join("images/005.png"))
        .unwrap();
    let err = run("ingest-colmap", d, json!({})).unwrap_err().to_string();
    assert!(
        err.contains("005.png") && err.contains("40×30") && err.contains("400×300"),
        "{err}"
    );
    std::fs::copy(dataset.join("images/005.png"), d.join("images/005.png")).unwrap();

    let mut tf: Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("transforms.json")).unwrap()).unwrap();
    tf["frames"][4]["transform_matrix"][0][0] = Value::Null;
    std::fs::write(d.join("transforms.json"), tf.to_string()).unwrap();
    let err = run("ingest-nerf", d, json!({})).unwrap_err().to_string();
    assert!(
        err.contains("transforms.json") && err.contains("frames[4].transform_matrix"),
        "{err}"
    );

    std::fs::write(d.join("sparse/0/cameras.bin"), [0u8; 5]).unwrap();
    let err = run("ingest-colmap", d, json!({})).unwrap_err().to_string();
    assert!(
        err.contains("cameras.bin") && err.contains("truncated"),
        "{err}"
    );
    let err = run("ingest-colmap", &d.join("nope"), json!({}))
        .unwrap_err()
        .to_string();
    assert!(err.contains("does not exist"), "{err}");
}

#[test]
fn blender_layout_with_clashing_file_names() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    for split in ["train", "test"] {
        std::fs::create_dir(d.join(split)).unwrap();
        image::RgbaImage::from_pixel(8, 8, image::Rgba([255, 0, 0, 128]))
            .save(d.join(format!("{split}/r_0.png")))
            .unwrap();
        let pose = [
            [1.0, 0.0, 0.0, 0.0],
            [0.0, 1.0, 0.0, 0.0],
            [0.0, 0.0, 1.0, 4.0],
            [0.0, 0.0, 0.0, 1.0],
        ];
        let doc = json!({"camera_angle_x": 0.69, "frames": [{"file_path": format!("./{split}/r_0"), "transform_matrix": pose}]});
        std::fs::write(d.join(format!("transforms_{split}.json")), doc.to_string()).unwrap();
    }
    let (dir, summary) = run("ingest-nerf", d, json!({})).unwrap();
    assert_eq!(
        (summary["train"].as_u64(), summary["test"].as_u64()),
        (Some(1), Some(1))
    );
    let s = scene_of(&dir);
    let names: Vec<&str> = s.views.iter().map(|v| v.name.as_str()).collect();
    assert_eq!(names, ["test/r_0.png", "train/r_0.png"]);
    let cam = &s.cameras[0];
    assert!((cam.fx - 4.0 / (0.345_f64).tan()).abs() < 1e-9 && cam.cx == 4.0);
    // OpenGL +z back becomes OpenCV +z forward: the camera at z=4 looks towards −z.
    assert_eq!(s.views[0].world_from_camera[2][2], -1.0);
}
