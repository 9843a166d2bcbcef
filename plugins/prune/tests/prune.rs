//! The pruning rule against hand-computed cases, and the stage end to end on a small scene.

use cocog_formats::splats::{Splats, logit};
use cocog_pipeline::{NullContext, Options, Scene, Stage, StageRequest};
use cocog_prune::{Prune, keep_mask};
use serde_json::json;

/// Gaussians at z = 0, 1, 2 (weights 1, 2, 3 with range 3) with chosen opacities.
fn splats(alphas: &[(f32, f32)]) -> Splats {
    let mut s = Splats::with_capacity(alphas.len(), 1);
    for (i, (z, a)) in alphas.iter().enumerate() {
        s.means.extend([i as f32, 0.0, *z]);
        s.log_scales.extend([-1.0, -2.0, -3.0]);
        s.rotations.extend([1.0, 0.0, 0.0, i as f32]);
        s.opacities.push(logit(*a));
        s.sh_dc.extend([i as f32; 3]);
        s.sh_rest.extend((0..9).map(|k| (i * 10 + k) as f32));
    }
    s
}

#[test]
fn threshold_relaxes_with_height() {
    // At z=0 the bar is 0.005, at z=1 0.0025, at z=2 0.005/3.
    let s = splats(&[
        (0.0, 0.0049),
        (0.0, 0.0051),
        (1.0, 0.0024),
        (1.0, 0.0026),
        (2.0, 0.0016),
        (2.0, 0.0017),
    ]);
    assert_eq!(
        keep_mask(&s, 0.005, 3.0),
        [false, true, false, true, false, true]
    );
    // With range 1 the bar is flat.
    assert_eq!(
        keep_mask(&s, 0.005, 1.0),
        [false, true, false, false, false, false]
    );
    let mut t = s.clone();
    t.retain(&[false, true, false, true, false, true]);
    assert_eq!(t.len(), 3);
    assert!(t.check().is_ok());
    assert_eq!(t.sh_dc, [1.0, 1.0, 1.0, 3.0, 3.0, 3.0, 5.0, 5.0, 5.0]);
    assert_eq!(&t.sh_rest[9..18], &s.sh_rest[27..36]);
    assert_eq!(&t.rotations[8..12], &[1.0, 0.0, 0.0, 5.0]);
}

#[test]
fn stage_prunes_the_scene_gaussians() {
    let tmp = tempfile::tempdir().unwrap();
    let input = tmp.path().join("in");
    std::fs::create_dir(&input).unwrap();
    let s = splats(&[(0.0, 0.001), (1.0, 0.9), (2.0, 0.5)]);
    cocog_formats::ply::write_splats(&input.join("gaussians.ply"), &s, None).unwrap();
    let mut scene = cocog_pipeline::testing::one_view_scene();
    scene.gaussians = Some("gaussians.ply".into());
    scene.save(&input).unwrap();
    let out = tmp.path().join("out");
    std::fs::create_dir(&out).unwrap();
    let info = Prune.info();
    let options =
        Options::validate(&info.name, &info.options, json!({}).as_object().unwrap()).unwrap();
    let summary = Prune
        .run(
            &StageRequest {
                input: input.clone(),
                output: out.clone(),
                options,
            },
            &NullContext,
        )
        .unwrap();
    assert_eq!(summary["removed"], 1);
    let scene = Scene::load(&out).unwrap();
    assert!(std::path::Path::new(&scene.views[0].image).is_absolute());
    let g = cocog_formats::ply::read_splats(&out.join("gaussians.ply")).unwrap();
    assert_eq!(g.len(), 2);
    assert_eq!(g.means[2], 1.0);

    let bad = Options::validate(
        &info.name,
        &info.options,
        json!({"range": 0.5}).as_object().unwrap(),
    )
    .unwrap();
    std::fs::remove_dir_all(&out).unwrap();
    std::fs::create_dir(&out).unwrap();
    let err = Prune
        .run(
            &StageRequest {
                input,
                output: out,
                options: bad,
            },
            &NullContext,
        )
        .unwrap_err()
        .to_string();
    assert!(err.contains("range"), "{err}");
}

#[test]
fn pruning_every_gaussian_or_none_at_all_is_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let prune = |s: &Splats, given: serde_json::Value| {
        let input = tmp.path().join("in");
        let out = tmp.path().join("out");
        for d in [&input, &out] {
            let _ = std::fs::remove_dir_all(d);
            std::fs::create_dir(d).unwrap();
        }
        cocog_formats::ply::write_splats(&input.join("gaussians.ply"), s, None).unwrap();
        let mut scene = cocog_pipeline::testing::one_view_scene();
        scene.gaussians = Some("gaussians.ply".into());
        scene.save(&input).unwrap();
        let info = Prune.info();
        let options =
            Options::validate(&info.name, &info.options, given.as_object().unwrap()).unwrap();
        let err = Prune
            .run(
                &StageRequest {
                    input,
                    output: out.clone(),
                    options,
                },
                &NullContext,
            )
            .unwrap_err();
        assert_eq!(
            std::fs::read_dir(&out).unwrap().count(),
            0,
            "nothing written"
        );
        err
    };
    let faint = splats(&[(0.0, 0.2), (1.0, 0.25)]);
    let err = prune(&faint, json!({"threshold": 0.9}));
    assert!(
        matches!(err, cocog_pipeline::StageError::Options(_))
            && err
                .to_string()
                .contains("threshold 0.9 with range 3 would remove all 2"),
        "{err}"
    );
    let err = prune(&splats(&[]), json!({})).to_string();
    assert!(err.contains("gaussians.ply: holds no Gaussians"), "{err}");
}
