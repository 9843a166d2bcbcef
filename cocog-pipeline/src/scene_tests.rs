use super::*;

fn identity() -> [[f64; 4]; 4] {
    [
        [1.0, 0.0, 0.0, 0.0],
        [0.0, 1.0, 0.0, 0.0],
        [0.0, 0.0, 1.0, 0.0],
        [0.0, 0.0, 0.0, 1.0],
    ]
}

fn sample() -> Scene {
    Scene {
        cameras: vec![Camera {
            id: 1,
            width: 40,
            height: 30,
            fx: 50.0,
            fy: 50.0,
            cx: 20.0,
            cy: 15.0,
        }],
        views: vec![View {
            name: "000".into(),
            image: "/data/images/000.png".into(),
            camera: 1,
            world_from_camera: identity(),
            split: Split::Test,
            lens: Some(Lens {
                focus_distance: 1.5,
                aperture: None,
            }),
            depth: None,
        }],
        bounds: Some(Bounds {
            near: 0.4,
            far: 2.3,
        }),
        ..Scene::default()
    }
}

#[test]
fn round_trips_through_disk() {
    let dir = tempfile::tempdir().expect("tempdir");
    let s = sample();
    s.save(dir.path()).expect("save");
    assert_eq!(Scene::load(dir.path()).expect("load"), s);
}

#[test]
fn missing_manifest_names_the_path() {
    let dir = tempfile::tempdir().expect("tempdir");
    let e = Scene::load(dir.path())
        .expect_err("no manifest")
        .to_string();
    assert!(e.contains("scene.json"), "{e}");
}

#[test]
fn corrupt_manifest_is_a_parse_error_with_position() {
    let dir = tempfile::tempdir().expect("tempdir");
    std::fs::write(dir.path().join(MANIFEST), "{\"format\": \"cocog.scene\",").expect("write");
    let e = Scene::load(dir.path()).expect_err("corrupt").to_string();
    assert!(e.contains("scene.json") && e.contains("line"), "{e}");
}

#[test]
fn unknown_major_version_is_refused_by_number() {
    let dir = tempfile::tempdir().expect("tempdir");
    let mut v = serde_json::to_value(sample()).expect("to_value");
    v["version"] = "2.0".into();
    v["cameras"] = "a field that changed shape in 2.0".into();
    std::fs::write(dir.path().join(MANIFEST), v.to_string()).expect("write");
    let e = Scene::load(dir.path()).expect_err("v2").to_string();
    assert!(e.contains("version 2.0") && e.contains("1.x"), "{e}");
}

#[test]
fn newer_minor_version_is_read() {
    let dir = tempfile::tempdir().expect("tempdir");
    let mut v = serde_json::to_value(sample()).expect("to_value");
    v["version"] = "1.7".into();
    std::fs::write(dir.path().join(MANIFEST), v.to_string()).expect("write");
    assert!(Scene::load(dir.path()).is_ok());
}

#[test]
fn invalid_content_names_the_field() {
    let mut s = sample();
    s.views[0].world_from_camera[0][3] = f64::NAN;
    assert!(
        s.validate()
            .unwrap_err()
            .contains("views[0] (000).world_from_camera")
    );
    let mut s = sample();
    s.views[0].camera = 9;
    assert!(s.validate().unwrap_err().contains("camera 9"));
    let mut s = sample();
    s.views[0].world_from_camera[0][0] = 2.0;
    assert!(s.validate().unwrap_err().contains("orthonormal"));
    let mut s = sample();
    s.cameras[0].fx = 0.0;
    assert!(s.validate().unwrap_err().contains("cameras[0]"));
}

#[test]
fn resolve_keeps_absolute_and_joins_relative() {
    let d = Path::new("/scenes/a");
    assert_eq!(Scene::resolve(d, "/x/y.png"), PathBuf::from("/x/y.png"));
    assert_eq!(
        Scene::resolve(d, "points.ply"),
        PathBuf::from("/scenes/a/points.ply")
    );
}

#[test]
fn rebase_makes_relative_paths_absolute() {
    let dir = tempfile::tempdir().expect("tempdir");
    let mut s = sample();
    s.views[0].image = "images/000.png".into();
    s.points = Some("points.ply".into());
    s.rebase(dir.path()).expect("rebase");
    let root = dir.path().canonicalize().expect("canonical");
    assert_eq!(
        PathBuf::from(&s.views[0].image),
        root.join("images/000.png")
    );
    assert_eq!(
        s.points.as_deref().map(PathBuf::from),
        Some(root.join("points.ply"))
    );
    assert!(s.rebase(&dir.path().join("missing")).is_err());
}
