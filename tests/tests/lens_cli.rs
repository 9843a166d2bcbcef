//! `cocog lens` compares learned focus distances with a dataset's metres after measuring the
//! scene's unit by the cameras both place, so a rescaled scene reads the same errors.

use std::path::Path;

use cocog_tests::{cocog, path_str, stderr, stdout, write_tiny_scene};
use serde_json::{Value, json};

const VIEWS: usize = 8;
const RADIUS: f64 = 2.0;

/// The tiny ring scene with photo-style names and a learned focus of RADIUS·(1 + i/100).
fn scene(dir: &Path) -> Value {
    write_tiny_scene(dir, VIEWS, [0.5, -1.0, 0.2], RADIUS);
    let path = dir.join("scene.json");
    let mut s: Value = serde_json::from_slice(&std::fs::read(&path).expect("read")).expect("json");
    for (i, v) in s["views"]
        .as_array_mut()
        .expect("views")
        .iter_mut()
        .enumerate()
    {
        v["name"] = json!(format!("{i:03}.png"));
        v["lens"]["focus_distance"] = json!(RADIUS * (1.0 + i as f64 / 100.0));
        // A learned aperture may come out negative: the report gives the diameter.
        v["lens"]["aperture"] = json!(if i % 2 == 0 { -0.25 } else { 0.25 });
    }
    std::fs::write(&path, s.to_string()).expect("write");
    s
}

/// A transforms.json placing the scene's cameras `metres` per scene unit apart (turned and
/// moved as well), every photo truly focused at the ring's radius.
fn truth(dir: &Path, scene: &Value, metres: f64, jitter: f64) -> std::path::PathBuf {
    truth_named(dir, scene, metres, jitter, |i| format!("images/{i:03}.png"))
}

/// The same, with photo `i` at `file_path(i)`.
fn truth_named(
    dir: &Path,
    scene: &Value,
    metres: f64,
    jitter: f64,
    file_path: fn(usize) -> String,
) -> std::path::PathBuf {
    let frames: Vec<Value> = scene["views"]
        .as_array()
        .expect("views")
        .iter()
        .enumerate()
        .map(|(i, v)| {
            let t: Vec<f64> = (0..3)
                .map(|r| v["world_from_camera"][r][3].as_f64().expect("t"))
                .collect();
            // A quarter turn about z, then an offset; `jitter` breaks the similarity.
            let wobble = jitter * (i * i) as f64;
            let c = [
                -metres * t[1] + 3.0 + wobble,
                metres * t[0] - 1.0,
                metres * t[2] + 0.5,
            ];
            json!({
                "file_path": file_path(i),
                "transform_matrix": [
                    [1.0, 0.0, 0.0, c[0]],
                    [0.0, 1.0, 0.0, c[1]],
                    [0.0, 0.0, 1.0, c[2]],
                    [0.0, 0.0, 0.0, 1.0]
                ],
                "focus_distance_m": metres * RADIUS,
            })
        })
        .collect();
    let t = json!({ "camera_angle_x": 0.9, "w": 40, "h": 30, "frames": frames });
    let path = dir.join(format!(
        "transforms-{metres}-{jitter}-{}.json",
        file_path(1).len()
    ));
    std::fs::write(&path, t.to_string()).expect("write transforms");
    path
}

fn lens_json(scene: &Path, truth: &Path) -> Value {
    let out = cocog(&[
        "lens",
        path_str(scene),
        "--truth",
        path_str(truth),
        "--json",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    serde_json::from_str(&stdout(&out)).expect("lens JSON")
}

#[test]
fn focus_errors_do_not_depend_on_the_scene_units() {
    let work = tempfile::tempdir().expect("tempdir");
    let s = scene(work.path());
    // Train views are those not held out (every 8th is a test view in the tiny scene).
    let train: Vec<usize> = (0..VIEWS).filter(|i| i % 8 != 0).collect();
    let mut errors: Vec<f64> = train.iter().map(|&i| i as f64 / 100.0).collect();
    errors.sort_by(f64::total_cmp);
    let expected = errors[errors.len() / 2];
    for metres in [0.1, 1.0, 25.0] {
        let r = lens_json(work.path(), &truth(work.path(), &s, metres, 0.0));
        let m = r["metres_per_scene_unit"].as_f64().expect("scale");
        assert!((m / metres - 1.0).abs() < 1e-9, "{metres}: {r}");
        assert_eq!(r["units_compared_as"].as_f64(), Some(m), "{r}");
        let median = r["median_focus_relative_error"].as_f64().expect("median");
        assert!(
            (median - expected).abs() < 1e-9,
            "{metres}: {median} vs {expected}"
        );
        let first = &r["views"][0];
        let focus = first["focus_distance"].as_f64().expect("scene units");
        let in_m = first["focus_distance_m"].as_f64().expect("metres");
        assert!((in_m - metres * focus).abs() < 1e-9, "{first}");
        for v in r["views"].as_array().expect("views") {
            let a = v["aperture_m"].as_f64().expect("aperture");
            assert!((a - metres * 0.25).abs() < 1e-9, "{v}");
        }
    }
    let table = cocog(&[
        "lens",
        path_str(work.path()),
        "--truth",
        path_str(&truth(work.path(), &s, 0.1, 0.0)),
    ]);
    let text = stdout(&table);
    assert!(text.contains("scene unit = 0.1000 m"), "{text}");
}

#[test]
fn cameras_that_disagree_are_reported_and_units_kept() {
    let work = tempfile::tempdir().expect("tempdir");
    let s = scene(work.path());
    let t = truth(work.path(), &s, 3.0, 0.2);
    let r = lens_json(work.path(), &t);
    assert!(
        r["camera_layout_spread"].as_f64().expect("spread") > 0.02,
        "{r}"
    );
    assert_eq!(r["units_compared_as"].as_f64(), Some(1.0), "{r}");
    let out = cocog(&["lens", path_str(work.path()), "--truth", path_str(&t)]);
    let text = stdout(&out);
    assert!(text.contains("not one similarity apart"), "{text}");
}

/// The truth's lenses found for the training views (001…007), in order.
fn matched(r: &Value) -> Vec<bool> {
    r["views"]
        .as_array()
        .expect("views")
        .iter()
        .map(|v| !v["true_focus_distance"].is_null())
        .collect()
}

#[test]
fn photos_match_by_name_whatever_their_folder_and_extension() {
    let work = tempfile::tempdir().expect("tempdir");
    let s = scene(work.path());
    let all = (VIEWS * (VIEWS - 1) / 2) as u64;
    // Another folder and extension (the scene has `NNN.png`), and Blender's bare `./train/NNN`.
    for path in [
        (|i| format!("images_4/{i:03}.JPG")) as fn(usize) -> String,
        |i| format!("./train/{i:03}"),
    ] {
        let r = lens_json(work.path(), &truth_named(work.path(), &s, 2.0, 0.0, path));
        assert_eq!(r["camera_pairs"].as_u64(), Some(all), "{r}");
        assert_eq!(matched(&r), [true; 7], "{r}");
    }
    // Only image extensions are dropped: photo `frame.001.png` is the truth's `x/frame.001`,
    // not one of seven `frame`s.
    let path = work.path().join("scene.json");
    let mut dotted = s.clone();
    for (i, v) in dotted["views"]
        .as_array_mut()
        .expect("views")
        .iter_mut()
        .enumerate()
    {
        v["name"] = json!(format!("frame.{i:03}.png"));
    }
    std::fs::write(&path, dotted.to_string()).expect("write");
    let t = truth_named(work.path(), &s, 2.0, 0.0, |i| format!("x/frame.{i:03}"));
    let r = lens_json(work.path(), &t);
    assert_eq!(matched(&r), [true; 7], "{r}");
    std::fs::write(&path, s.to_string()).expect("write");
    // Frame 2 is a `.jpg` of photo 001: two frames name 001, so neither names it, for the
    // lenses and for the camera pairs that measure the unit alike.
    let twice = truth_named(work.path(), &s, 2.0, 0.0, |i| match i {
        2 => "images/001.jpg".into(),
        _ => format!("images/{i:03}.png"),
    });
    let r = lens_json(work.path(), &twice);
    assert_eq!(
        matched(&r),
        [false, false, true, true, true, true, true],
        "{r}"
    );
    assert_eq!(r["camera_pairs"].as_u64(), Some(15), "{r}");
    // The same on the scene's side: views 001 and 003 both named `NNN/001.png`.
    let mut renamed = s.clone();
    renamed["views"][1]["name"] = json!("a/001.png");
    renamed["views"][3]["name"] = json!("b/001.png");
    std::fs::write(&path, renamed.to_string()).expect("write");
    let r = lens_json(work.path(), &truth(work.path(), &s, 2.0, 0.0));
    assert_eq!(
        matched(&r),
        [false, true, false, true, true, true, true],
        "{r}"
    );
    assert_eq!(r["camera_pairs"].as_u64(), Some(15), "{r}");
}
