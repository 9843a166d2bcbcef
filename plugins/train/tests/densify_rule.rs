//! The INRIA densification rule on a hand-built case whose outcome is worked out by hand.

use cocog_engine::GaussianParams;
use cocog_train::{
    DensifyConfig, DepthAxis, Origin, SplitNoise, apply_plan, gather_rows, inverse_sigmoid,
    plan_densify,
};

/// Five Gaussians, extent 1 (so clone/split boundary 0.01, "large" 0.1):
/// 0 hot and small → clone; 1 hot and large (0.05, rotated) → split; 2 cold → keep;
/// 3 hot and small but faint → clone, then both pruned; 4 cold and very large → kept unless
/// large ones are pruned.
fn case() -> (GaussianParams, Vec<f32>) {
    let h = std::f32::consts::FRAC_1_SQRT_2;
    let g = GaussianParams {
        sh_degree: 0,
        means: vec![[0.0; 3], [1.0, 2.0, 3.0], [0.5; 3], [-1.0; 3], [2.0; 3]],
        log_scales: vec![
            [0.005f32.ln(); 3],
            [0.05f32.ln(), 0.02f32.ln(), 0.01f32.ln()],
            [0.05f32.ln(); 3],
            [0.002f32.ln(); 3],
            [0.2f32.ln(); 3],
        ],
        // Gaussian 1 is turned 90° about z, so its long axis lies along world y.
        quats: vec![
            [1.0, 0.0, 0.0, 0.0],
            [h, 0.0, 0.0, h],
            [1.0, 0.0, 0.0, 0.0],
            [2.0, 0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0, 0.0],
        ],
        opacity_logits: vec![0.5, 1.0, 1.5, inverse_sigmoid(0.001), 2.0],
        sh: (0..15).map(|v| v as f32).collect(),
    };
    (g, vec![1e-3, 2e-4, 1e-4, 5e-3, 0.0])
}

#[test]
fn clone_split_and_prune_follow_the_inria_rule() {
    let (g, grads) = case();
    let config = DensifyConfig::default();
    let plan = plan_densify(
        &g,
        &grads,
        1.0,
        false,
        &config,
        &SplitNoise {
            seed: 3,
            iteration: 600,
        },
        None,
    );
    // Originals minus the split one, then clones (0 and 3), then two children of 1; the faint
    // original 3 and its clone are pruned.
    let sources: Vec<String> = plan.origins.iter().map(|o| format!("{o:?}")).collect();
    assert_eq!(
        (plan.cloned, plan.split, plan.pruned),
        (2, 1, 2),
        "{sources:?}"
    );
    assert_eq!(
        &plan.origins[..4],
        &[
            Origin::Keep(0),
            Origin::Keep(2),
            Origin::Keep(4),
            Origin::Clone(0)
        ]
    );
    assert_eq!(plan.origins.len(), 6);
    let out = apply_plan(&g, &plan);
    out.validate().unwrap();
    for child in 4..6 {
        let Origin::Split { parent: 1, .. } = plan.origins[child] else {
            panic!("expected a child of 1, got {:?}", plan.origins[child]);
        };
        let expected = [0.05f32 / 1.6, 0.02 / 1.6, 0.01 / 1.6];
        for (l, e) in out.log_scales[child].iter().zip(expected) {
            assert!((l.exp() - e).abs() < 1e-6);
        }
        // Offsets follow the rotated scales: along world y up to ~5σ = 0.25, along z ≤ 0.05.
        let d: Vec<f32> = (0..3)
            .map(|a| out.means[child][a] - g.means[1][a])
            .collect();
        assert!(
            d[1].abs() < 0.25 && d[0].abs() < 0.1 && d[2].abs() < 0.05,
            "{d:?}"
        );
        assert!(d.iter().any(|v| *v != 0.0));
        assert_eq!(out.quats[child], g.quats[1]);
        assert_eq!(out.opacity_logits[child], 1.0);
        assert_eq!(&out.sh[3 * child..3 * child + 3], &[3.0, 4.0, 5.0]);
    }
    assert_ne!(
        out.means[4], out.means[5],
        "the two children are sampled independently"
    );
    // The clone of 0 is an exact copy.
    assert_eq!(
        (out.means[3], out.log_scales[3]),
        (g.means[0], g.log_scales[0])
    );
    // Moments: survivors keep theirs, new Gaussians start at zero.
    let moments: Vec<f32> = (0..5).map(|i| 10.0 + i as f32).collect();
    assert_eq!(
        gather_rows(&moments, 1, &plan.origins, true),
        [10.0, 12.0, 14.0, 0.0, 0.0, 0.0]
    );
}

#[test]
fn after_the_first_reset_large_gaussians_are_pruned_and_seeds_repeat() {
    let (g, grads) = case();
    let config = DensifyConfig::default();
    let plan = plan_densify(
        &g,
        &grads,
        1.0,
        true,
        &config,
        &SplitNoise {
            seed: 3,
            iteration: 600,
        },
        None,
    );
    assert!(!plan.origins.contains(&Origin::Keep(4)));
    assert_eq!(plan.pruned, 3);
    let again = plan_densify(
        &g,
        &grads,
        1.0,
        true,
        &config,
        &SplitNoise {
            seed: 3,
            iteration: 600,
        },
        None,
    );
    assert_eq!(plan, again);
    // Schedule: densify in (500, 15000) every 100, reset every 3000 below 15000.
    assert!(!config.densifies_at(500) && config.densifies_at(600) && !config.densifies_at(650));
    assert!(!config.densifies_at(15_000));
    assert!(config.resets_opacity_at(3000) && !config.resets_opacity_at(15_000));
}

/// Deblurring 3DGS's depth-weighted pruning: the threshold falls from t at the nearest
/// Gaussian to t / range at the farthest, so an equally faint far Gaussian survives.
#[test]
fn far_gaussians_survive_a_depth_weighted_prune() {
    let faint = inverse_sigmoid(0.003);
    // Cameras at the origin looking down +z; Gaussians at depths 1, 2 and 3.
    let g = GaussianParams {
        sh_degree: 0,
        means: vec![[0.0, 0.0, 1.0], [0.0, 0.0, 2.0], [0.0, 0.0, 3.0]],
        log_scales: vec![[0.001f32.ln(); 3]; 3],
        quats: vec![[1.0, 0.0, 0.0, 0.0]; 3],
        opacity_logits: vec![faint; 3],
        sh: vec![0.0; 9],
    };
    let grads = [0.0; 3];
    let axis = DepthAxis::from_cameras(&[[0.0; 3], [0.1, 0.0, 0.0]], &[[0.0, 0.0, 1.0]; 2]);
    let uniform = DensifyConfig::default();
    let weighted = DensifyConfig {
        depth_prune_range: 3.0,
        ..DensifyConfig::default()
    };
    let plan = |c: &DensifyConfig, axis| {
        plan_densify(
            &g,
            &grads,
            1.0,
            false,
            c,
            &SplitNoise {
                seed: 1,
                iteration: 600,
            },
            axis,
        )
    };
    // 0.003 < 0.005: all pruned uniformly.
    assert_eq!(plan(&uniform, Some(&axis)).origins.len(), 0);
    // Weighted: thresholds 0.005, 0.0025, 0.00167 at depths 1, 2, 3 → the two far ones stay.
    let kept = plan(&weighted, Some(&axis)).origins;
    assert_eq!(kept, vec![Origin::Keep(1), Origin::Keep(2)]);
    // Without an axis the rule cannot weigh depth and prunes uniformly.
    assert_eq!(plan(&weighted, None).origins.len(), 0);
    // Cameras facing every way: depth is the distance from their centre.
    let around = DepthAxis::from_cameras(
        &[[0.0, 0.0, -5.0], [0.0, 0.0, 5.0]],
        &[[0.0, 0.0, 1.0], [0.0, 0.0, -1.0]],
    );
    assert!(around.forward.is_none());
    assert!((around.depth([3.0, 4.0, 0.0]) - 5.0).abs() < 1e-12);
}
