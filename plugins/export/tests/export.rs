//! Export to .ply and .glb: the files read back to the scene's Gaussians.

use std::path::Path;

use cocog_export::{Export, axis_name};
use cocog_formats::splats::Splats;
use cocog_pipeline::{NullContext, Options, Stage, StageRequest};
use serde_json::json;

fn scene_with_gaussians(dir: &Path, with: bool) -> Splats {
    let mut s = Splats::with_capacity(3, 1);
    for i in 0..3 {
        s.means.extend([i as f32, 1.0, -2.0]);
        s.log_scales.extend([-1.0, -2.0, -3.0]);
        s.rotations.extend([1.0, 0.0, 0.0, 0.0]);
        s.opacities.push(0.5 * i as f32);
        s.sh_dc.extend([0.1, 0.2, 0.3]);
        s.sh_rest.extend((0..9).map(|k| k as f32 * 0.01));
    }
    std::fs::create_dir_all(dir).unwrap();
    let mut scene = cocog_pipeline::testing::one_view_scene();
    scene.up = Some([0.1, -0.2, 0.95]);
    if with {
        cocog_formats::ply::write_splats(&dir.join("g.ply"), &s, None).unwrap();
        scene.gaussians = Some("g.ply".into());
    }
    scene.save(dir).unwrap();
    s
}

fn export(
    input: &Path,
    output: &Path,
    format: &str,
) -> Result<serde_json::Value, cocog_pipeline::StageError> {
    let info = Export.info();
    let options = Options::validate(
        &info.name,
        &info.options,
        json!({"format": format}).as_object().unwrap(),
    )?;
    Export.run(
        &StageRequest {
            input: input.to_path_buf(),
            output: output.to_path_buf(),
            options,
        },
        &NullContext,
    )
}

#[test]
fn exports_ply_glb_and_spz() {
    let tmp = tempfile::tempdir().unwrap();
    let s = scene_with_gaussians(&tmp.path().join("scene"), true);
    let ply = tmp.path().join("out.ply");
    export(&tmp.path().join("scene"), &ply, "ply").unwrap();
    assert_eq!(cocog_formats::ply::read_splats(&ply).unwrap(), s);
    let header = std::fs::read(&ply).unwrap();
    assert!(String::from_utf8_lossy(&header[..400]).contains("comment Vertical axis: z"));
    let glb = tmp.path().join("out.glb");
    let summary = export(&tmp.path().join("scene"), &glb, "glb").unwrap();
    assert_eq!(summary["gaussians"], 3);
    let back = cocog_formats::glb::read_glb(&glb).unwrap();
    assert_eq!(
        (back.means, back.sh_dc, back.sh_rest),
        (s.means, s.sh_dc, s.sh_rest)
    );
    let spz = tmp.path().join("out.spz");
    let summary = export(&tmp.path().join("scene"), &spz, "spz").unwrap();
    assert_eq!(summary["format"], "spz");
    // gzip, which holds the header's "NGSP".
    assert_eq!(&std::fs::read(&spz).unwrap()[..2], &[0x1f, 0x8b]);
    let err = export(
        &tmp.path().join("scene"),
        &tmp.path().join("x.splat"),
        "splat",
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("ply, glb or spz"), "{err}");
}

#[test]
fn a_scene_without_gaussians_is_refused() {
    let tmp = tempfile::tempdir().unwrap();
    scene_with_gaussians(&tmp.path().join("scene"), false);
    let err = export(&tmp.path().join("scene"), &tmp.path().join("o.ply"), "ply")
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("gaussians") && err.contains("scene.json"),
        "{err}"
    );
    assert!(!tmp.path().join("o.ply").exists());
    assert_eq!(axis_name([0.0, -0.9, 0.1]), "-y");
}

#[test]
fn a_scene_with_no_gaussians_exports_nothing() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("scene");
    scene_with_gaussians(&dir, true);
    cocog_formats::ply::write_splats(&dir.join("g.ply"), &Splats::with_capacity(0, 1), None)
        .unwrap();
    for format in ["ply", "spz", "glb"] {
        let out = tmp.path().join(format!("o.{format}"));
        let err = export(&dir, &out, format).unwrap_err().to_string();
        assert!(err.contains("g.ply: holds no Gaussians"), "{format}: {err}");
        assert!(!out.exists());
    }
}
