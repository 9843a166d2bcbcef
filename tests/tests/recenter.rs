//! The example plugin, built as a cdylib, found through --plugin-path and run on a scene.

use cocog_tests::{cdylib, cocog, path_str, stderr, stdout, write_tiny_scene};
use serde_json::Value;

fn centre_of(view: &Value) -> [f64; 3] {
    let m = &view["world_from_camera"];
    [0, 1, 2].map(|r| m[r][3].as_f64().expect("pose entry"))
}

#[test]
fn recenter_plugin_normalises_a_scene() {
    let lib = cdylib("cocog-plugin-recenter");
    let plugins = tempfile::tempdir().expect("tempdir");
    std::fs::copy(&lib, plugins.path().join(lib.file_name().expect("name"))).expect("copy");
    let work = tempfile::tempdir().expect("tempdir");
    let input = work.path().join("scene");
    write_tiny_scene(&input, 8, [10.0, -4.0, 3.0], 5.0);
    let output = work.path().join("centred");

    let listing = cocog(&["plugins", "--plugin-path", path_str(plugins.path())]);
    assert!(
        stdout(&listing).contains("recenter"),
        "{}",
        stdout(&listing)
    );

    let out = cocog(&[
        "stage",
        "recenter",
        path_str(&input),
        "-o",
        path_str(&output),
        "--set",
        "radius=2",
        "--plugin-path",
        path_str(plugins.path()),
        "--json",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let summary: Value = serde_json::from_slice(&out.stdout).expect("--json summary");
    assert!((summary["scale"].as_f64().expect("scale") - 0.4).abs() < 1e-12);

    let scene: Value = serde_json::from_str(
        &std::fs::read_to_string(output.join("scene.json")).expect("output scene.json"),
    )
    .expect("json");
    let views = scene["views"].as_array().expect("views");
    let centres: Vec<[f64; 3]> = views.iter().map(centre_of).collect();
    for k in 0..3 {
        let mean: f64 = centres.iter().map(|c| c[k]).sum::<f64>() / centres.len() as f64;
        assert!(
            mean.abs() < 1e-9,
            "mean camera centre not at origin: {mean}"
        );
    }
    for c in &centres {
        let r = (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt();
        assert!((r - 2.0).abs() < 1e-9, "camera at distance {r}, expected 2");
    }
    // Lengths scale by 0.4: focus distance 5 -> 2, aperture 10 -> 4, bounds too.
    assert!((views[0]["lens"]["focus_distance"].as_f64().expect("f") - 2.0).abs() < 1e-12);
    assert!((views[0]["lens"]["aperture"].as_f64().expect("k") - 4.0).abs() < 1e-12);
    assert!((scene["bounds"]["far"].as_f64().expect("far") - 4.0).abs() < 1e-12);
    // The points moved with the cameras: the scene centre lands on the origin.
    let cloud = cocog_formats::ply::read_points(&output.join("points.ply")).expect("points");
    let p = &cloud.positions;
    assert!(
        p[0].abs() < 1e-5 && p[1].abs() < 1e-5 && p[2].abs() < 1e-5,
        "{p:?}"
    );
    assert!(
        (p[3] - 0.4).abs() < 1e-5 && (p[5] + 0.2).abs() < 1e-5,
        "{p:?}"
    );
    assert_eq!(cloud.colors, vec![255, 0, 0, 0, 255, 0]);
    // History names the stage and where it came from.
    let h = &scene["history"][0];
    assert_eq!(h["stage"], "recenter");
    assert!(
        h["provider"]
            .as_str()
            .expect("provider")
            .contains("plugin recenter")
    );
    assert_eq!(h["options"]["radius"], 2.0);
}
