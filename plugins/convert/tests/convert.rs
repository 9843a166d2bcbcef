//! Convert round trips: ingest a bench scene, convert it, ingest the result, same scene.

use std::path::{Path, PathBuf};

use cocog_pipeline::{NullContext, Options, Scene, Stage, StageError, StageRequest};
use serde_json::{Value, json};

fn dev_scene() -> Option<PathBuf> {
    let p =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/bench/defocus-dev/dev-shelf");
    if !p.is_dir() {
        eprintln!("SKIP: bench data not found at {}", p.display());
        return None;
    }
    Some(p)
}

fn run(
    stage: Box<dyn Stage>,
    input: &Path,
    output: &Path,
    options: Value,
) -> Result<Value, StageError> {
    let info = stage.info();
    let options = Options::validate(&info.name, &info.options, options.as_object().unwrap())?;
    std::fs::create_dir(output).unwrap();
    stage.run(
        &StageRequest {
            input: input.to_path_buf(),
            output: output.to_path_buf(),
            options,
        },
        &NullContext,
    )
}

fn ingest(name: &str) -> Box<dyn Stage> {
    cocog_ingest::stages()
        .into_iter()
        .find(|s| s.info().name == name)
        .unwrap()
}

fn assert_same(a: &Scene, b: &Scene, tol: f64) {
    assert_eq!(a.cameras, b.cameras);
    assert_eq!(a.views.len(), b.views.len());
    for (x, y) in a.views.iter().zip(&b.views) {
        assert_eq!((&x.name, x.split, x.camera), (&y.name, y.split, y.camera));
        let d = x
            .world_from_camera
            .iter()
            .flatten()
            .zip(y.world_from_camera.iter().flatten())
            .map(|(p, q)| (p - q).abs())
            .fold(0.0, f64::max);
        assert!(d < tol, "{}: {d}", x.name);
    }
}

#[test]
fn colmap_and_nerf_round_trip() {
    let Some(dataset) = dev_scene() else { return };
    let tmp = tempfile::tempdir().unwrap();
    let t = tmp.path();
    run(
        ingest("ingest-colmap"),
        &dataset,
        &t.join("scene"),
        json!({}),
    )
    .unwrap();
    let original = Scene::load(&t.join("scene")).unwrap();

    run(
        Box::new(cocog_convert::Convert),
        &t.join("scene"),
        &t.join("as-colmap"),
        json!({"to": "colmap"}),
    )
    .unwrap();
    assert!(t.join("as-colmap/images/000.png").is_file());
    run(
        ingest("ingest-colmap"),
        &t.join("as-colmap"),
        &t.join("back-colmap"),
        json!({}),
    )
    .unwrap();
    let back = Scene::load(&t.join("back-colmap")).unwrap();
    assert_same(&original, &back, 1e-12);
    let [p0, p1] = [t.join("scene/points.ply"), t.join("back-colmap/points.ply")]
        .map(|p| cocog_formats::ply::read_points(&p).unwrap());
    assert_eq!(p0, p1);

    run(
        Box::new(cocog_convert::Convert),
        &t.join("scene"),
        &t.join("as-nerf"),
        json!({"to": "nerf"}),
    )
    .unwrap();
    run(
        ingest("ingest-nerf"),
        &t.join("as-nerf"),
        &t.join("back-nerf"),
        json!({}),
    )
    .unwrap();
    let back = Scene::load(&t.join("back-nerf")).unwrap();
    assert_same(&original, &back, 1e-12);
    // The points travel too: named by `ply_file_path` and read back by ingest nerf.
    let transforms: Value =
        serde_json::from_str(&std::fs::read_to_string(t.join("as-nerf/transforms.json")).unwrap())
            .unwrap();
    assert_eq!(transforms["ply_file_path"], "points.ply");
    let stored = back
        .points
        .as_deref()
        .expect("ingest nerf reads ply_file_path");
    let p2 =
        cocog_formats::ply::read_points(&Scene::resolve(&t.join("back-nerf"), stored)).unwrap();
    assert_eq!(p0, p2);

    let err = run(
        Box::new(cocog_convert::Convert),
        &t.join("scene"),
        &t.join("x"),
        json!({"to": "blender"}),
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("colmap or nerf"), "{err}");
}
