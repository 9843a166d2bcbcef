//! COLMAP model I/O: round trips, bench bin vs txt, pycolmap cross-checks, and corrupt files.

mod common;

use cocog_formats::colmap::{
    self, Camera, CameraModel, Image, Model, Point2D, Point3D, TrackElement,
};

/// A model touching every camera model, empty keypoint lists, untracked keypoints and huge ids.
fn synthetic_model() -> Model {
    let cameras = CameraModel::ALL
        .iter()
        .enumerate()
        .map(|(i, &model)| Camera {
            id: 10 + i as u32 * 3,
            model,
            width: 640 + i as u64,
            height: 480,
            params: (0..model.num_params())
                .map(|k| 100.0 + k as f64 * 0.125 + i as f64 / 7.0)
                .collect(),
        })
        .collect::<Vec<_>>();
    let images = (0..5u32)
        .map(|i| Image {
            id: 1000 - i * 7,
            qvec: [0.5 + i as f64 * 0.1, -0.2, 0.3, 0.1 * i as f64],
            tvec: [1.0 / 3.0, -2.5 * i as f64, 1e-9],
            camera_id: cameras[i as usize % cameras.len()].id,
            name: format!("dir/img_{i}.png"),
            points2d: (0..i * 2)
                .map(|k| Point2D {
                    xy: [k as f64 + 0.5, 100.0 / (k as f64 + 3.0)],
                    point3d_id: (k % 3 != 0).then_some(u64::MAX - 2 - k as u64),
                })
                .collect(),
        })
        .collect();
    let points = (0..4u64)
        .map(|i| Point3D {
            id: if i == 3 { u64::MAX - 1 } else { i * 11 },
            xyz: [i as f64 * 0.1, -1.0 / 7.0, 2.0e5],
            rgb: [i as u8 * 60, 255, 0],
            error: if i == 0 { -1.0 } else { 0.123 * i as f64 },
            track: (0..i as u32)
                .map(|k| TrackElement {
                    image_id: 1000 - k * 7,
                    point2d_idx: k,
                })
                .collect(),
        })
        .collect();
    Model {
        cameras,
        images,
        points,
    }
}

#[test]
fn bin_and_txt_round_trip_exactly() {
    let model = synthetic_model();
    let dir = tempfile::tempdir().unwrap();
    colmap::write_bin(&model, dir.path()).unwrap();
    assert_eq!(colmap::read_bin(dir.path()).unwrap(), model);
    colmap::write_txt(&model, dir.path()).unwrap();
    assert_eq!(colmap::read_txt(dir.path()).unwrap(), model);
    // No temp files are left behind by the atomic writer.
    let names: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(names.len(), 6, "{names:?}");
}

#[test]
fn bench_bin_and_txt_agree() {
    for scene in common::dev_scenes() {
        let dir = scene.join("sparse/0");
        let bin = colmap::read_bin(&dir).unwrap();
        let txt = colmap::read_txt(&dir).unwrap();
        assert_eq!(bin.images.len(), 24);
        assert!(bin.points.len() > 1000);
        assert_eq!(bin.cameras, txt.cameras);
        assert_eq!(bin.images.len(), txt.images.len());
        let mut txt_images = txt.images.clone();
        // COLMAP's bin and txt writers order images differently; compare by id.
        txt_images.sort_by_key(|i| bin.images.iter().position(|b| b.id == i.id));
        for (a, b) in bin.images.iter().zip(&txt_images) {
            assert_eq!((a.id, &a.name, a.camera_id), (b.id, &b.name, b.camera_id));
            // COLMAP's text writer prints 17 significant digits, so values agree to rounding.
            for (x, y) in a
                .qvec
                .iter()
                .chain(&a.tvec)
                .zip(b.qvec.iter().chain(&b.tvec))
            {
                assert!((x - y).abs() < 1e-14, "{} pose {x} vs {y}", a.name);
            }
            assert_eq!(a.points2d.len(), b.points2d.len());
        }
        let mut txt_points = txt.points.clone();
        txt_points.sort_by_key(|p| bin.points.iter().position(|b| b.id == p.id));
        for (a, b) in bin.points.iter().zip(&txt_points) {
            assert_eq!((a.id, a.rgb, &a.track), (b.id, b.rgb, &b.track));
            for (x, y) in a.xyz.iter().zip(&b.xyz) {
                assert!((x - y).abs() <= 1e-12 * x.abs().max(1.0));
            }
        }
        assert_eq!(
            colmap::find_model_dir(&scene, None).unwrap(),
            scene.join("sparse/0")
        );
    }
}

const DUMP: &str = r#"
import json, sys, pycolmap
rec = pycolmap.Reconstruction(sys.argv[1])
out = {"cameras": {}, "images": {}, "points": {}}
for cid, c in rec.cameras.items():
    out["cameras"][cid] = [c.model.name, c.width, c.height, list(map(float, c.params))]
for iid, im in rec.images.items():
    cfw = im.cam_from_world() if callable(im.cam_from_world) else im.cam_from_world
    x, y, z, w = map(float, cfw.rotation.quat)
    out["images"][iid] = [im.name, im.camera_id, [w, x, y, z], list(map(float, cfw.translation)),
        [[float(p.xy[0]), float(p.xy[1]), int(p.point3D_id)] for p in im.points2D]]
for pid, p in rec.points3D.items():
    out["points"][str(pid)] = [list(map(float, p.xyz)), list(map(int, p.color)), float(p.error),
        [[e.image_id, e.point2D_idx] for e in p.track.elements]]
if len(sys.argv) > 2:
    rec.write_binary(sys.argv[2])
print(json.dumps(out))
"#;

fn assert_matches_pycolmap(model: &Model, dump: &serde_json::Value) {
    let close =
        |a: f64, b: &serde_json::Value| (a - b.as_f64().unwrap()).abs() <= 1e-12 * a.abs().max(1.0);
    assert_eq!(
        dump["cameras"].as_object().unwrap().len(),
        model.cameras.len()
    );
    for c in &model.cameras {
        let d = &dump["cameras"][c.id.to_string()];
        assert_eq!(d[0], c.model.name(), "camera {}", c.id);
        assert_eq!(
            (d[1].as_u64(), d[2].as_u64()),
            (Some(c.width), Some(c.height))
        );
        let params = d[3].as_array().unwrap();
        assert_eq!(params.len(), c.params.len());
        assert!(c.params.iter().zip(params).all(|(a, b)| close(*a, b)));
    }
    assert_eq!(
        dump["images"].as_object().unwrap().len(),
        model.images.len()
    );
    for im in &model.images {
        let d = &dump["images"][im.id.to_string()];
        assert_eq!(
            (d[0].as_str(), d[1].as_u64()),
            (Some(im.name.as_str()), Some(u64::from(im.camera_id)))
        );
        // pycolmap normalises the quaternion; compare against ours normalised, up to sign.
        let unit = |q: &[f64]| {
            let n = q.iter().map(|v| v * v).sum::<f64>().sqrt();
            q.iter().map(|v| v / n).collect::<Vec<_>>()
        };
        let q = unit(
            &d[2]
                .as_array()
                .unwrap()
                .iter()
                .map(|v| v.as_f64().unwrap())
                .collect::<Vec<_>>(),
        );
        let ours = unit(&im.qvec);
        let sign = if q.iter().zip(&ours).map(|(a, b)| a * b).sum::<f64>() < 0.0 {
            -1.0
        } else {
            1.0
        };
        assert!(
            q.iter()
                .zip(&ours)
                .all(|(a, b)| (sign * a - b).abs() < 1e-12),
            "{q:?} vs {:?}",
            im.qvec
        );
        assert!(
            im.tvec
                .iter()
                .zip(d[3].as_array().unwrap())
                .all(|(a, b)| close(*a, b))
        );
        let pts = d[4].as_array().unwrap();
        assert_eq!(pts.len(), im.points2d.len());
        for (p, q) in im.points2d.iter().zip(pts) {
            assert!(close(p.xy[0], &q[0]) && close(p.xy[1], &q[1]));
            assert_eq!(p.point3d_id.unwrap_or(u64::MAX), q[2].as_u64().unwrap());
        }
    }
    assert_eq!(
        dump["points"].as_object().unwrap().len(),
        model.points.len()
    );
    for p in &model.points {
        let d = &dump["points"][p.id.to_string()];
        assert!(
            p.xyz
                .iter()
                .zip(d[0].as_array().unwrap())
                .all(|(a, b)| close(*a, b))
        );
        let rgb: Vec<u64> = d[1]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_u64().unwrap())
            .collect();
        assert_eq!(rgb, p.rgb.map(u64::from));
        assert!(close(p.error, &d[2]));
        let track: Vec<(u64, u64)> = d[3]
            .as_array()
            .unwrap()
            .iter()
            .map(|e| (e[0].as_u64().unwrap(), e[1].as_u64().unwrap()))
            .collect();
        let ours: Vec<(u64, u64)> = p
            .track
            .iter()
            .map(|t| (u64::from(t.image_id), u64::from(t.point2d_idx)))
            .collect();
        assert_eq!(track, ours);
    }
}

/// A model pycolmap accepts: it rejects dangling references, so tracks and keypoints must agree.
fn consistent_model() -> Model {
    let mut model = synthetic_model();
    for img in &mut model.images {
        img.points2d.iter_mut().for_each(|p| p.point3d_id = None);
    }
    for (k, p) in model.points.iter_mut().enumerate() {
        // COLMAP's text reader parses point ids as signed 64-bit.
        p.id = 5 + k as u64 * 1_000_003;
        p.track.clear();
        let img = &mut model.images[4];
        img.points2d[k].point3d_id = Some(p.id);
        p.track.push(TrackElement {
            image_id: img.id,
            point2d_idx: k as u32,
        });
    }
    model
}

#[test]
fn pycolmap_reads_what_we_write() {
    if !common::python_has(&["pycolmap"]) {
        return;
    }
    let model = consistent_model();
    for text in [false, true] {
        let dir = tempfile::tempdir().unwrap();
        if text {
            colmap::write_txt(&model, dir.path()).unwrap();
        } else {
            colmap::write_bin(&model, dir.path()).unwrap();
        }
        let out = common::run_python(DUMP, &[dir.path().to_str().unwrap()]);
        assert_matches_pycolmap(&model, &serde_json::from_str(&out).unwrap());
    }
}

#[test]
fn we_read_what_pycolmap_reads_and_writes() {
    if !common::python_has(&["pycolmap"]) {
        return;
    }
    for scene in common::dev_scenes() {
        let ours = colmap::read_model(&scene.join("sparse/0")).unwrap();
        let rewritten = tempfile::tempdir().unwrap();
        let out = common::run_python(
            DUMP,
            &[
                scene.join("sparse/0").to_str().unwrap(),
                rewritten.path().to_str().unwrap(),
            ],
        );
        let dump: serde_json::Value = serde_json::from_str(&out).unwrap();
        assert_matches_pycolmap(&ours, &dump);
        // Our text reader agrees with pycolmap too (it read the .bin; COLMAP's .txt is 17 digits).
        assert_matches_pycolmap(&colmap::read_txt(&scene.join("sparse/0")).unwrap(), &dump);
        // pycolmap 4 writes rigs.bin and frames.bin too; our reader ignores them and must still agree.
        let theirs = colmap::read_bin(rewritten.path()).unwrap();
        assert_matches_pycolmap(&theirs, &dump);
    }
}

#[test]
fn corrupt_binary_files_name_file_and_field() {
    let model = synthetic_model();
    let dir = tempfile::tempdir().unwrap();
    colmap::write_bin(&model, dir.path()).unwrap();
    for file in ["cameras.bin", "images.bin", "points3D.bin"] {
        let path = dir.path().join(file);
        let good = std::fs::read(&path).unwrap();
        // Truncated anywhere.
        for cut in [0, 5, 8, 13, good.len() / 2, good.len() - 1] {
            std::fs::write(&path, &good[..cut]).unwrap();
            let err = colmap::read_bin(dir.path()).unwrap_err().to_string();
            assert!(err.contains(file), "{err}");
            assert!(err.contains("truncated") || err.contains("count"), "{err}");
        }
        // A count that is one too small leaves trailing bytes; one too large runs out of data.
        for delta in [-1i64, 1, 1 << 40] {
            let mut bad = good.clone();
            let n = u64::from_le_bytes(bad[..8].try_into().unwrap()) as i64 + delta;
            bad[..8].copy_from_slice(&(n as u64).to_le_bytes());
            std::fs::write(&path, &bad).unwrap();
            let err = colmap::read_bin(dir.path()).unwrap_err().to_string();
            assert!(
                err.contains(file) && (err.contains("num_") || err.contains("truncated")),
                "{err}"
            );
        }
        std::fs::write(&path, &good).unwrap();
    }
    // An unknown camera model id.
    let path = dir.path().join("cameras.bin");
    let mut bad = std::fs::read(&path).unwrap();
    bad[12..16].copy_from_slice(&99i32.to_le_bytes());
    std::fs::write(&path, &bad).unwrap();
    let err = colmap::read_bin(dir.path()).unwrap_err().to_string();
    assert!(
        err.contains("cameras.bin") && err.contains("camera[0].model_id") && err.contains("99"),
        "{err}"
    );
}

#[test]
fn corrupt_text_files_name_line_and_field() {
    let dir = tempfile::tempdir().unwrap();
    colmap::write_txt(&synthetic_model(), dir.path()).unwrap();
    let cams = dir.path().join("cameras.txt");
    std::fs::write(&cams, "1 PINHOLE 640 480 500 500 320\n").unwrap();
    let err = colmap::read_txt(dir.path()).unwrap_err().to_string();
    assert!(
        err.contains("cameras.txt") && err.contains("line 1") && err.contains("needs 4"),
        "{err}"
    );
    std::fs::write(&cams, "1 PINHOLE 640 abc 500 500 320 240\n").unwrap();
    let err = colmap::read_txt(dir.path()).unwrap_err().to_string();
    assert!(err.contains("HEIGHT") && err.contains("\"abc\""), "{err}");
    std::fs::write(&cams, "1 PINHOLE 640 480 500 500 320 240\n").unwrap();
    // Images now point at cameras that no longer exist.
    let err = colmap::read_txt(dir.path()).unwrap_err().to_string();
    assert!(
        err.contains("images") && err.contains("not in cameras"),
        "{err}"
    );
}

#[test]
fn nan_pose_is_refused() {
    let mut model = synthetic_model();
    model.images[2].tvec[1] = f64::NAN;
    let dir = tempfile::tempdir().unwrap();
    colmap::write_bin(&model, dir.path()).unwrap();
    let err = colmap::read_bin(dir.path()).unwrap_err().to_string();
    assert!(
        err.contains("NaN") && err.contains("dir/img_2.png"),
        "{err}"
    );
}

#[test]
fn duplicate_ids_are_refused_naming_file_and_id() {
    let model = synthetic_model();
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // Each record kind, in each encoding: the second record takes the first one's id.
    type Spoil = fn(&mut Model) -> String;
    let cases: [(&str, Spoil, &str); 3] = [
        (
            "cameras",
            |m| {
                m.cameras[1].id = m.cameras[0].id;
                m.cameras[1].params[0] += 1.0;
                format!("duplicate camera id {}", m.cameras[0].id)
            },
            "CAMERA_ID",
        ),
        (
            "images",
            |m| {
                m.images[3].id = m.images[1].id;
                format!("duplicate image id {}", m.images[1].id)
            },
            "IMAGE_ID",
        ),
        (
            "points3D",
            |m| {
                m.points[2].id = m.points[3].id;
                format!("duplicate point3D id {}", m.points[3].id)
            },
            "POINT3D_ID",
        ),
    ];
    for (stem, spoil, txt_field) in cases {
        let mut bad = model.clone();
        let expect = spoil(&mut bad);
        colmap::write_bin(&bad, d).unwrap();
        let err = colmap::read_bin(d).unwrap_err().to_string();
        assert!(
            err.contains(&format!("{stem}.bin")) && err.contains(&expect),
            "{err}"
        );
        colmap::write_txt(&bad, d).unwrap();
        let err = colmap::read_txt(d).unwrap_err().to_string();
        assert!(
            err.contains(&format!("{stem}.txt"))
                && err.contains(txt_field)
                && err.contains(&expect)
                && err.contains("line "),
            "{err}"
        );
    }
    // The same id in two different files is not a duplicate (ids are per kind).
    let mut ok = model;
    ok.points[0].id = u64::from(ok.images[0].id);
    colmap::write_bin(&ok, d).unwrap();
    assert_eq!(colmap::read_bin(d).unwrap(), ok);
}

#[test]
fn text_files_with_a_byte_order_mark_read() {
    let model = synthetic_model();
    let dir = tempfile::tempdir().unwrap();
    colmap::write_txt(&model, dir.path()).unwrap();
    for file in ["cameras.txt", "images.txt", "points3D.txt"] {
        let path = dir.path().join(file);
        let text = std::fs::read_to_string(&path).unwrap();
        // Without the comment header the BOM sits right before the first record's id.
        let data: String = text
            .lines()
            .filter(|l| !l.starts_with('#'))
            .map(|l| format!("{l}\n"))
            .collect();
        std::fs::write(&path, format!("\u{feff}{data}")).unwrap();
    }
    assert_eq!(colmap::read_txt(dir.path()).unwrap(), model);
    // A BOM anywhere else is still an error.
    let cams = dir.path().join("cameras.txt");
    let text = std::fs::read_to_string(&cams).unwrap();
    std::fs::write(&cams, text.replacen('\n', "\n\u{feff}", 1)).unwrap();
    let err = colmap::read_txt(dir.path()).unwrap_err().to_string();
    assert!(
        err.contains("cameras.txt") && err.contains("line 2"),
        "{err}"
    );
}

#[test]
fn a_camera_line_one_field_short_says_which_fields() {
    let dir = tempfile::tempdir().unwrap();
    colmap::write_txt(&synthetic_model(), dir.path()).unwrap();
    // HEIGHT is missing: the four parameters shift left and look like three.
    std::fs::write(
        dir.path().join("cameras.txt"),
        "1 PINHOLE 640 500 500 320 240\n",
    )
    .unwrap();
    let err = colmap::read_txt(dir.path()).unwrap_err().to_string();
    assert!(
        err.contains("line 1")
            && err.contains("CAMERA_ID MODEL WIDTH HEIGHT, 8 fields in all; the line has 7")
            && err.contains("HEIGHT or a parameter missing"),
        "{err}"
    );
}
