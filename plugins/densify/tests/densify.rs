//! Extra points against a brute-force f64 reference, and the stage on a bench scene.

use std::path::{Path, PathBuf};

use cocog_densify::{SplitMix64, extra_points, robust_box};
use cocog_formats::PointCloud;
use cocog_pipeline::{NullContext, Options, Scene, Stage, StageRequest};
use serde_json::json;

#[test]
fn splitmix_matches_the_published_sequence() {
    // First outputs of Vigna's splitmix64.c for seed 0.
    let mut r = SplitMix64::new(0);
    assert_eq!(r.next_u64(), 0xE220_A839_7B1D_CDAF);
    assert_eq!(r.next_u64(), 0x6E78_9E6A_A1B9_65F4);
}

fn cloud(n: usize) -> PointCloud {
    let mut r = SplitMix64::new(42);
    PointCloud {
        positions: (0..3 * n)
            .map(|_| (r.next_f64() * 10.0 - 5.0) as f32)
            .collect(),
        colors: (0..3 * n).map(|_| (r.next_u64() % 256) as u8).collect(),
    }
}

#[test]
fn extra_points_match_a_brute_force_reference() {
    let c = cloud(300);
    let (count, max_d, seed) = (2000, 1.2, 9);
    let got = extra_points(&c, count, max_d, seed, |_| false).unwrap();
    // Replay the candidates and decide each one by exhaustive search.
    let (lo, hi) = robust_box(&c);
    let mut sorted_x: Vec<f32> = c.positions.iter().step_by(3).copied().collect();
    sorted_x.sort_by(f32::total_cmp);
    assert_eq!(lo[0], f64::from(sorted_x[10]));
    assert_eq!(hi[0], f64::from(sorted_x[289]));
    let mut rng = SplitMix64::new(seed);
    let mut kept = 0;
    let mut dropped = 0;
    for _ in 0..count {
        let p: [f64; 3] = std::array::from_fn(|a| lo[a] + (hi[a] - lo[a]) * rng.next_f64());
        let mut d: Vec<(f64, usize)> = c
            .positions
            .chunks_exact(3)
            .enumerate()
            .map(|(j, q)| {
                (
                    (0..3)
                        .map(|a| (p[a] - f64::from(q[a])).powi(2))
                        .sum::<f64>()
                        .sqrt(),
                    j,
                )
            })
            .collect();
        d.sort_by(|a, b| a.0.total_cmp(&b.0));
        let near: Vec<_> = d[..4].iter().filter(|(dist, _)| *dist < max_d).collect();
        if near.is_empty() {
            dropped += 1;
            continue;
        }
        let total: f64 = near.iter().map(|(dist, _)| dist).sum();
        assert_eq!(
            &got.points.positions[3 * kept..3 * kept + 3],
            &p.map(|v| v as f32)
        );
        for ch in 0..3 {
            let want: f64 = near
                .iter()
                .map(|(dist, j)| dist / total * f64::from(c.colors[3 * j + ch]))
                .sum();
            let have = f64::from(got.points.colors[3 * kept + ch]);
            assert!(
                (have - want).abs() <= 0.5 + 1e-9,
                "point {kept} ch {ch}: {have} vs {want}"
            );
        }
        kept += 1;
    }
    assert_eq!((kept, dropped), (got.points.len(), got.dropped));
    assert!(
        dropped > 0 && kept > 0,
        "the test should exercise both branches: {kept} kept, {dropped} dropped"
    );
}

fn dev_scene() -> Option<PathBuf> {
    let p =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/bench/defocus-dev/dev-table");
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
    options: serde_json::Value,
) -> Result<serde_json::Value, cocog_pipeline::StageError> {
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

#[test]
fn densify_a_bench_scene() {
    let Some(dataset) = dev_scene() else { return };
    let tmp = tempfile::tempdir().unwrap();
    let ingest = cocog_ingest::stages()
        .into_iter()
        .find(|s| s.info().name == "ingest-colmap")
        .unwrap();
    run(ingest, &dataset, &tmp.path().join("s1"), json!({})).unwrap();
    let t = std::time::Instant::now();
    let summary = run(
        Box::new(cocog_densify::Densify),
        &tmp.path().join("s1"),
        &tmp.path().join("s2"),
        json!({"seed": 3}),
    )
    .unwrap();
    let secs = t.elapsed().as_secs_f64();
    eprintln!("densify dev-table: {summary} in {secs:.2} s");
    let added = summary["added"].as_u64().unwrap();
    assert!((150_000..=250_000).contains(&added), "{added}");
    let scene = Scene::load(&tmp.path().join("s2")).unwrap();
    assert!(Path::new(&scene.views[0].image).is_absolute());
    let before = cocog_formats::ply::read_points(&tmp.path().join("s1/points.ply")).unwrap();
    let after = cocog_formats::ply::read_points(&tmp.path().join("s2/points.ply")).unwrap();
    assert_eq!(after.len(), before.len() + added as usize);
    assert_eq!(
        &after.positions[..before.positions.len()],
        &before.positions[..]
    );
    // Sensible colours: every sampled new point lies within the colour range of its 4 nearest
    // SfM points (found here by exhaustive search), so no colour is invented.
    let n0 = before.len();
    for i in (n0..after.len()).step_by(401) {
        let p = &after.positions[3 * i..3 * i + 3];
        let mut d: Vec<(f32, usize)> = before
            .positions
            .chunks_exact(3)
            .enumerate()
            .map(|(j, q)| ((0..3).map(|a| (p[a] - q[a]).powi(2)).sum::<f32>(), j))
            .collect();
        d.sort_by(|a, b| a.0.total_cmp(&b.0));
        for ch in 0..3 {
            let near: Vec<u8> = d[..4]
                .iter()
                .map(|(_, j)| before.colors[3 * j + ch])
                .collect();
            let c = after.colors[3 * i + ch];
            assert!(
                near.iter().min().unwrap() <= &c && &c <= near.iter().max().unwrap(),
                "point {i}: {c} outside {near:?}"
            );
        }
    }
    // Running again on a scene without points fails with the field named.
    let mut bare = scene;
    bare.points = None;
    std::fs::create_dir(tmp.path().join("bare")).unwrap();
    bare.save(&tmp.path().join("bare")).unwrap();
    let err = run(
        Box::new(cocog_densify::Densify),
        &tmp.path().join("bare"),
        &tmp.path().join("s3"),
        json!({}),
    )
    .unwrap_err()
    .to_string();
    assert!(
        err.contains("scene.json") && err.contains("points"),
        "{err}"
    );
}
