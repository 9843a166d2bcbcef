//! Requests `render` cannot serve fail before any GPU work, naming what is wrong.

mod common;

use cocog_pipeline::{Scene, Split, StageError};
use common::{reference_png, run, stage, write_scene};
use serde_json::json;

#[test]
fn bad_requests_name_what_is_wrong() {
    let tmp = tempfile::tempdir().unwrap();
    let (png, _) = reference_png();
    let scene = tmp.path().join("scene");
    write_scene(&scene, &png);
    let out = tmp.path().join("out");
    let render = stage("render");
    let err = run(
        render.as_ref(),
        &scene,
        &out,
        json!({"focus_distance": 2.0}),
    )
    .unwrap_err();
    assert!(matches!(err, StageError::Input(_)), "{err:?}");
    assert!(err.to_string().contains("--method cocog"), "{err}");
    let err = run(render.as_ref(), &scene, &out, json!({"split": "dev"})).unwrap_err();
    assert!(err.to_string().contains("test, train or all"), "{err}");

    let mut s = Scene::load(&scene).unwrap();
    s.views.retain(|v| v.split == Split::Train);
    s.save(&scene).unwrap();
    let err = run(render.as_ref(), &scene, &out, json!({})).unwrap_err();
    assert!(matches!(err, StageError::Input(_)), "{err:?}");
    for needle in ["no test views", "--split all"] {
        assert!(err.to_string().contains(needle), "{needle:?} not in {err}");
    }

    s.gaussians = None;
    s.save(&scene).unwrap();
    let err = run(render.as_ref(), &scene, &out, json!({"split": "all"})).unwrap_err();
    assert!(matches!(err, StageError::Input(_)), "{err:?}");
    assert!(err.to_string().contains("`gaussians`"), "{err}");
}
