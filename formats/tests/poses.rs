//! LLFF, COLMAP and transforms.json: readers agree with each other on the bench scenes, with
//! numpy-written files, and refuse bad input with a message naming file and field.

mod common;

use std::collections::BTreeMap;
use std::path::Path;

use cocog_formats::colmap::{self, Pinhole};
use cocog_formats::llff::{self, LlffView};
use cocog_formats::nerf::{self, NerfFrameOut};
use cocog_formats::pose::{self, Mat4};
use npyz::WriterBuilder;

fn max_diff(a: &Mat4, b: &Mat4) -> f64 {
    a.iter()
        .flatten()
        .zip(b.iter().flatten())
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
}

fn file_name(p: &str) -> String {
    Path::new(p)
        .file_name()
        .unwrap()
        .to_string_lossy()
        .into_owned()
}

#[test]
fn bench_llff_colmap_and_transforms_agree() {
    for scene in common::dev_scenes() {
        let mut names: Vec<String> = std::fs::read_dir(scene.join("images"))
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        let llff = llff::read_poses_bounds(&scene.join("poses_bounds.npy")).unwrap();
        assert_eq!(llff.len(), names.len());
        let model = colmap::read_model(&scene.join("sparse/0")).unwrap();
        let frames = nerf::read_dataset(&scene).unwrap();
        let by_name_colmap: BTreeMap<String, _> =
            model.images.iter().map(|i| (i.name.clone(), i)).collect();
        let by_name_nerf: BTreeMap<String, _> = frames
            .iter()
            .map(|f| (file_name(&f.file_path), f))
            .collect();
        let hold = llff::read_hold_marker(&scene).unwrap();
        assert_eq!(hold, Some(8));
        for (i, (name, view)) in names.iter().zip(&llff).enumerate() {
            let img = by_name_colmap[name];
            let frame = by_name_nerf[name];
            let c = img.world_from_camera();
            assert!(
                max_diff(&view.world_from_camera, &c) < 1e-5,
                "{name}: LLFF vs COLMAP {}",
                max_diff(&view.world_from_camera, &c)
            );
            assert!(
                max_diff(&frame.world_from_camera, &c) < 1e-5,
                "{name}: transforms vs COLMAP {}",
                max_diff(&frame.world_from_camera, &c)
            );
            // Intrinsics: COLMAP PINHOLE, LLFF's hwf and transforms.json describe one camera.
            let p = model.camera(img.camera_id).unwrap().pinhole().unwrap();
            let cam = model.camera(img.camera_id).unwrap();
            assert_eq!(
                [view.hwf[0], view.hwf[1]],
                [cam.height as f64, cam.width as f64]
            );
            assert!((view.hwf[2] - p.fx).abs() < 1e-6);
            assert_eq!(
                frame
                    .camera
                    .pinhole(cam.width as f64, cam.height as f64)
                    .unwrap(),
                p
            );
            // The split: hold=8 marks every 8th name-sorted view as test, as transforms.json says.
            let test = i % 8 == 0;
            assert_eq!(
                frame.split.as_deref(),
                Some(if test { "test" } else { "train" }),
                "{name}"
            );
            assert!(view.near > 0.0 && view.near < view.far);
        }
    }
}

fn sample_views() -> Vec<LlffView> {
    (0..5)
        .map(|i| {
            let q = [1.0, 0.1 * i as f64, -0.2, 0.05 * i as f64];
            let (r, _) = pose::to_rt(&pose::world_from_colmap(q, [0.0; 3]));
            let world_from_camera =
                pose::from_rt(r, glam::DVec3::new(i as f64, -1.5, 0.25 * i as f64));
            LlffView {
                world_from_camera,
                hwf: [300.0, 400.0, 388.5],
                near: 0.5,
                far: 2.0 + i as f64,
            }
        })
        .collect()
}

#[test]
fn llff_round_trips_through_our_writer() {
    let views = sample_views();
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("poses_bounds.npy");
    llff::write_poses_bounds(&p, &views).unwrap();
    let back = llff::read_poses_bounds(&p).unwrap();
    for (a, b) in views.iter().zip(&back) {
        assert!(max_diff(&a.world_from_camera, &b.world_from_camera) < 1e-15);
        assert_eq!((a.hwf, a.near, a.far), (b.hwf, b.near, b.far));
    }
}

/// numpy builds the LLFF rows itself from OpenCV poses with the published formula
/// `[R | C | hwf]` with R columns [down, right, back] and saves f4/f8 in C and Fortran order.
#[test]
fn llff_reads_numpy_files_in_every_dtype_and_order() {
    if !common::python_has(&["numpy"]) {
        return;
    }
    let views = sample_views();
    let dir = tempfile::tempdir().unwrap();
    let poses: Vec<Vec<Vec<f64>>> = views
        .iter()
        .map(|v| {
            v.world_from_camera[..3]
                .iter()
                .map(|r| r.to_vec())
                .collect()
        })
        .collect();
    let script = r#"
import json, sys, numpy as np
c2w = np.array(json.loads(sys.argv[1]))              # N x 3 x 4, OpenCV axes
r, d, f, c = c2w[:, :, 0], c2w[:, :, 1], c2w[:, :, 2], c2w[:, :, 3]
hwf = np.tile([300.0, 400.0, 388.5], (len(c2w), 1))
m = np.stack([d, r, -f, c, hwf], axis=2)              # N x 3 x 5
bounds = np.stack([np.full(len(c2w), 0.5), 2.0 + np.arange(len(c2w))], axis=1)
rows = np.concatenate([m.reshape(len(c2w), 15), bounds], axis=1)
for dt in ["<f4", "<f8", ">f8"]:
    np.save(f"{sys.argv[2]}/c_{dt[1:]}_{dt[0] == '>'}.npy", np.ascontiguousarray(rows.astype(dt)))
    np.save(f"{sys.argv[2]}/f_{dt[1:]}_{dt[0] == '>'}.npy", np.asfortranarray(rows.astype(dt)))
"#;
    common::run_python(
        script,
        &[
            &serde_json::to_string(&poses).unwrap(),
            dir.path().to_str().unwrap(),
        ],
    );
    let mut seen = 0;
    for entry in std::fs::read_dir(dir.path()).unwrap() {
        let p = entry.unwrap().path();
        let tol = if p.to_string_lossy().contains("f4") {
            1e-6
        } else {
            1e-14
        };
        let back = llff::read_poses_bounds(&p).unwrap_or_else(|e| panic!("{e}"));
        for (a, b) in views.iter().zip(&back) {
            assert!(
                max_diff(&a.world_from_camera, &b.world_from_camera) < tol * 10.0,
                "{}",
                p.display()
            );
            assert!((a.far - b.far).abs() < tol * 10.0);
        }
        seen += 1;
    }
    assert_eq!(seen, 6);
}

fn write_npy(path: &Path, shape: &[u64], data: &[f64]) {
    let mut f = std::fs::File::create(path).unwrap();
    let mut w = npyz::WriteOptions::new()
        .default_dtype()
        .shape(shape)
        .writer(&mut f)
        .begin_nd()
        .unwrap();
    w.extend(data.iter().copied()).unwrap();
    w.finish().unwrap();
}

#[test]
fn llff_bad_input_is_refused_with_a_reason() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("poses_bounds.npy");
    write_npy(&p, &[3, 15], &[0.0; 45]);
    let err = llff::read_poses_bounds(&p).unwrap_err().to_string();
    assert!(
        err.contains("poses_bounds.npy") && err.contains("shape") && err.contains("(N, 17)"),
        "{err}"
    );

    llff::write_poses_bounds(&p, &sample_views()).unwrap();
    let mut bytes = std::fs::read(&p).unwrap();
    let header = bytes.len() - 5 * 17 * 8;
    bytes[header + 17 * 8 + 3 * 8..header + 17 * 8 + 4 * 8]
        .copy_from_slice(&f64::NAN.to_le_bytes());
    std::fs::write(&p, &bytes).unwrap();
    let err = llff::read_poses_bounds(&p).unwrap_err().to_string();
    assert!(err.contains("row 1: pose") && err.contains("NaN"), "{err}");

    std::fs::write(&p, b"\x93NUMPY garbage").unwrap();
    let err = llff::read_poses_bounds(&p).unwrap_err().to_string();
    assert!(err.contains("header"), "{err}");

    std::fs::write(dir.path().join("hold=x"), b"").unwrap();
    let err = llff::read_hold_marker(dir.path()).unwrap_err().to_string();
    assert!(err.contains("hold=x"), "{err}");
}

#[test]
fn transforms_round_trip_and_bad_input() {
    let views = sample_views();
    let out: Vec<NerfFrameOut> = views
        .iter()
        .enumerate()
        .map(|(i, v)| NerfFrameOut {
            file_path: format!("images/{i:03}.png"),
            world_from_camera: v.world_from_camera,
            intrinsics: Pinhole {
                fx: 388.5,
                fy: 390.0,
                cx: 201.0,
                cy: 149.5,
            },
            width: 400,
            height: 300,
            split: Some(if i % 2 == 0 { "test" } else { "train" }.into()),
        })
        .collect();
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("transforms.json");
    nerf::write_transforms(&p, &out, None).unwrap();
    let back = nerf::read_dataset(dir.path()).unwrap();
    for (a, b) in out.iter().zip(&back) {
        assert_eq!(a.file_path, b.file_path);
        assert!(max_diff(&a.world_from_camera, &b.world_from_camera) < 1e-15);
        assert_eq!(b.camera.pinhole(400.0, 300.0).unwrap(), a.intrinsics);
        assert_eq!(a.split, b.split);
    }

    let text = std::fs::read_to_string(&p).unwrap();
    let mut v: serde_json::Value = serde_json::from_str(&text).unwrap();
    v["frames"][2]["transform_matrix"][1][2] = serde_json::Value::Null;
    std::fs::write(&p, v.to_string()).unwrap();
    let err = nerf::read_dataset(dir.path()).unwrap_err().to_string();
    assert!(
        err.contains("frames[2].transform_matrix") && err.contains("[1][2]"),
        "{err}"
    );

    v["frames"][2]["transform_matrix"][1][2] = serde_json::json!(3.0);
    std::fs::write(&p, v.to_string()).unwrap();
    let err = nerf::read_dataset(dir.path()).unwrap_err().to_string();
    assert!(err.contains("not orthonormal"), "{err}");

    let blender = serde_json::json!({"camera_angle_x": 0.69, "k1": 0.1, "frames": []});
    std::fs::write(&p, blender.to_string()).unwrap();
    let err = nerf::read_dataset(dir.path()).unwrap_err().to_string();
    assert!(err.contains("k1") && err.contains("distorted"), "{err}");
}

#[test]
fn blender_angle_gives_the_textbook_focal() {
    let cam = nerf::NerfCamera {
        camera_angle_x: Some(0.6911112070083618),
        ..Default::default()
    };
    let p = cam.pinhole(800.0, 800.0).unwrap();
    assert!((p.fx - 1111.1110311937682).abs() < 1e-6 && p.fy == p.fx && p.cx == 400.0);
}
