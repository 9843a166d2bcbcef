//! COLMAP numbers out of range (NaN, infinity, zero sizes, zero quaternions) are refused at read,
//! naming the file, the record's id and the field, in both `.bin` and `.txt`.

use cocog_formats::colmap::{self, Camera, CameraModel, Image, Model, Point3D};

fn small_model() -> Model {
    Model {
        cameras: vec![Camera {
            id: 7,
            model: CameraModel::Pinhole,
            width: 64,
            height: 48,
            params: vec![50.0, 50.0, 32.0, 24.0],
        }],
        images: [(3, "a.png"), (4, "b.png")]
            .map(|(id, name)| Image {
                id,
                qvec: [1.0, 0.0, 0.0, 0.0],
                tvec: [0.0, 0.0, 1.0],
                camera_id: 7,
                name: name.into(),
                points2d: vec![],
            })
            .to_vec(),
        points: [11, 12]
            .map(|id| Point3D {
                id,
                xyz: [0.5, -0.5, 2.0],
                rgb: [1, 2, 3],
                error: 0.5,
                track: vec![],
            })
            .to_vec(),
    }
}

/// Writes `model` in both encodings and returns each read's error message.
fn errors(model: &Model) -> [String; 2] {
    let bin = tempfile::tempdir().unwrap();
    colmap::write_bin(model, bin.path()).unwrap();
    let txt = tempfile::tempdir().unwrap();
    colmap::write_txt(model, txt.path()).unwrap();
    [
        colmap::read_bin(bin.path()).unwrap_err().to_string(),
        colmap::read_txt(txt.path()).unwrap_err().to_string(),
    ]
}

fn assert_names(errors: [String; 2], file: &str, parts: &[&str]) {
    for (err, ext) in errors.iter().zip(["bin", "txt"]) {
        let want = format!("{file}.{ext}");
        assert!(err.contains(&want), "expected {want} in: {err}");
        for p in parts {
            assert!(err.contains(p), "expected {p:?} in: {err}");
        }
        assert!(
            !err.contains("Some(") && !err.contains(" {"),
            "Debug dump: {err}"
        );
    }
}

#[test]
fn non_finite_point_coordinates_are_refused() {
    let mut m = small_model();
    m.points[1].xyz[2] = f64::NAN;
    assert_names(errors(&m), "points3D", &["point3D 12", "xyz[2]", "NaN"]);
    m.points[1].xyz[2] = f64::NEG_INFINITY;
    assert_names(errors(&m), "points3D", &["point3D 12", "xyz[2]", "-inf"]);
}

#[test]
fn non_finite_camera_params_and_zero_sizes_are_refused() {
    let mut m = small_model();
    m.cameras[0].params[1] = f64::INFINITY;
    assert_names(errors(&m), "cameras", &["camera 7", "params[1]", "inf"]);
    let mut m = small_model();
    m.cameras[0].width = 0;
    assert_names(errors(&m), "cameras", &["camera 7", "width", "got 0"]);
    let mut m = small_model();
    m.cameras[0].height = 0;
    assert_names(errors(&m), "cameras", &["camera 7", "height", "got 0"]);
}

#[test]
fn bad_image_poses_are_refused() {
    let mut m = small_model();
    m.images[1].qvec[2] = f64::NAN;
    assert_names(errors(&m), "images", &["image 4 (b.png)", "qvec[2]", "NaN"]);
    let mut m = small_model();
    m.images[0].tvec[0] = f64::INFINITY;
    assert_names(errors(&m), "images", &["image 3 (a.png)", "tvec[0]", "inf"]);
    let mut m = small_model();
    m.images[0].qvec = [0.0; 4];
    assert_names(errors(&m), "images", &["image 3 (a.png)", "qvec", "zero"]);
}

#[test]
fn pinhole_focal_lengths_name_the_parameter() {
    let mut cam = small_model().cameras.remove(0);
    cam.params[1] = 0.0;
    let err = cam.pinhole().unwrap_err();
    assert!(
        err.contains("params[1]") && err.contains("fy") && !err.contains("0.0,"),
        "{err}"
    );
    cam.params[1] = 1e308;
    let err = cam.pinhole().unwrap_err();
    assert!(err.contains("fy") && err.contains("at most"), "{err}");
}
