//! transforms.json numbers out of range are refused at read, naming the file, the frame and the
//! key; focal lengths derived later (from the image's own size) name the key too.

use std::path::Path;

use cocog_formats::nerf::{self, NerfCamera};
use serde_json::{Value, json};

const POSE: [[f64; 4]; 4] = [
    [1.0, 0.0, 0.0, 0.0],
    [0.0, 1.0, 0.0, 0.0],
    [0.0, 0.0, 1.0, 4.0],
    [0.0, 0.0, 0.0, 1.0],
];

fn doc() -> Value {
    json!({
        "camera_angle_x": 0.69,
        "w": 800, "h": 600,
        "frames": [
            {"file_path": "./images/000", "transform_matrix": POSE},
            {"file_path": "./images/001", "transform_matrix": POSE},
        ]
    })
}

/// The error of reading `text` as a transforms.json.
fn read_err(text: &str) -> String {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("transforms.json"), text).unwrap();
    match nerf::read_dataset(dir.path()) {
        Ok(frames) => panic!("accepted: {frames:?}"),
        Err(e) => e.to_string(),
    }
}

fn assert_clear(err: &str, parts: &[&str]) {
    assert!(err.contains("transforms.json"), "no file in: {err}");
    for p in parts {
        assert!(err.contains(p), "expected {p:?} in: {err}");
    }
    assert!(
        !err.contains("Pinhole {") && !err.contains("Some("),
        "Debug dump: {err}"
    );
}

#[test]
fn camera_angle_must_be_a_real_field_of_view() {
    for bad in [json!(0), json!(-0.5), json!(4.0)] {
        let mut d = doc();
        d["camera_angle_x"] = bad;
        assert_clear(&read_err(&d.to_string()), &["camera_angle_x", "expected"]);
    }
    // JSON has no NaN, but 1e400 overflows f64.
    let text = doc().to_string().replace("0.69", "1e400");
    assert_clear(&read_err(&text), &[]);
}

#[test]
fn focal_lengths_must_be_finite_positive_and_sane() {
    for bad in [json!(0), json!(-100.0), json!(1e308)] {
        let mut d = doc();
        d["frames"][1]["fl_x"] = bad;
        assert_clear(
            &read_err(&d.to_string()),
            &["frames[1]", "./images/001", "fl_x", "expected"],
        );
    }
    let mut d = doc();
    d["fl_y"] = json!(-1);
    assert_clear(&read_err(&d.to_string()), &["fl_y", "expected"]);
}

#[test]
fn image_size_must_be_at_least_one_pixel() {
    for key in ["w", "h"] {
        let mut d = doc();
        d["frames"][0][key] = json!(0);
        assert_clear(
            &read_err(&d.to_string()),
            &["frames[0]", &format!(".{key}"), "got 0"],
        );
    }
}

#[test]
fn transform_matrix_must_be_finite_and_4x4() {
    let mut d = doc();
    d["frames"][1]["transform_matrix"] = json!([[1, 0, 0], [0, 1, 0], [0, 0, 1], [0, 0, 0]]);
    assert_clear(
        &read_err(&d.to_string()),
        &[
            "frames[1].transform_matrix",
            "./images/001",
            "4×4",
            "row 0 has 3",
        ],
    );
    let mut d = doc();
    d["frames"][1]["transform_matrix"] = json!([[1, 0, 0, 0]]);
    assert_clear(
        &read_err(&d.to_string()),
        &["frames[1].transform_matrix", "got 1 row"],
    );
    let mut d = doc();
    d["frames"][0]["transform_matrix"][2][3] = json!("far");
    assert_clear(
        &read_err(&d.to_string()),
        &[
            "frames[0].transform_matrix",
            "./images/000",
            "[2][3]",
            "\"far\"",
        ],
    );
}

#[test]
fn focal_from_the_image_size_names_the_key() {
    // Blender files give no size: the focal is derived later from the image's own width.
    let cam = NerfCamera {
        camera_angle_x: Some(1e-300),
        ..Default::default()
    };
    let err = cam.pinhole(800.0, 800.0).unwrap_err();
    assert!(
        err.contains("camera_angle_x") && !err.contains("Pinhole {"),
        "{err}"
    );
    let cam = NerfCamera {
        fl_x: Some(1e300),
        ..Default::default()
    };
    let err = cam.pinhole(800.0, 800.0).unwrap_err();
    assert!(err.contains("fl_x") && !err.contains("Pinhole {"), "{err}");
}

#[test]
fn frames_know_their_file() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("transforms.json"), doc().to_string()).unwrap();
    let frames = nerf::read_dataset(dir.path()).unwrap();
    assert_eq!(frames[1].index, 1);
    assert_eq!(
        frames[1].source.file_name(),
        Some(Path::new("transforms.json").as_os_str())
    );
}

#[test]
fn transform_matrix_last_row_is_shown_plainly() {
    let mut d = doc();
    d["frames"][1]["transform_matrix"][3][3] = json!(2);
    assert_clear(
        &read_err(&d.to_string()),
        &["frames[1].transform_matrix", "row 3", "[0, 0, 0, 2]"],
    );
}

#[test]
fn pythons_nan_and_infinity_are_named() {
    let text = doc().to_string();
    for word in ["NaN", "Infinity", "-Infinity"] {
        let bad = text.replacen("4.0", word, 1);
        assert!(bad.contains(word));
        let err = read_err(&bad);
        assert_clear(&err, &["NaN or Infinity", "allow_nan=False", "line 1"]);
    }
    // Other syntax errors keep serde_json's own words.
    let err = read_err(&text.replacen("4.0", "fourish", 1));
    assert!(!err.contains("NaN"), "{err}");
}
