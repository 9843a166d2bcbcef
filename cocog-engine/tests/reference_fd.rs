//! Finite differences on the f64 CPU reference validate its analytic backward, for every
//! parameter group and every SH band.

mod common;

use cocog_engine::reference::{Gaussians64, Image64, render, render_backward};
use common::{random_scene, random_weights, test_camera};

fn loss(img: &Image64, w: &(Vec<[f64; 3]>, Vec<f64>, Vec<f64>)) -> f64 {
    let mut l = 0.0;
    for p in 0..img.color.len() {
        l += (0..3).map(|k| img.color[p][k] * w.0[p][k]).sum::<f64>();
        l += img.alpha[p] * w.1[p] + img.depth[p] * w.2[p];
    }
    l
}

fn check(n: usize, sh_degree: u32, seed: u64) {
    let cam = test_camera(64, 48, 0.2);
    let bg = [0.2, 0.5, 0.9];
    let mut g = Gaussians64::from(&random_scene(n, sh_degree, seed, &cam));
    // Push one colour channel below zero so the clamp (and its zero gradient) is exercised.
    let stride = 3 * (sh_degree as usize + 1).pow(2);
    g.sh[0] = -4.0;
    g.sh[stride + stride / 3] = -4.0;
    let w = random_weights(64 * 48, seed + 1);
    let analytic = render_backward(&g, &cam, bg, &w.0, &w.1, &w.2).scalars();
    let eps = 1e-6;
    let count = g.scalars_mut().len();
    let names: Vec<&str> = g.scalars_mut().iter().map(|(n, _)| *n).collect();
    let mut worst: std::collections::BTreeMap<&str, (f64, usize, usize)> = Default::default();
    for i in 0..count {
        let orig = *g.scalars_mut()[i].1;
        *g.scalars_mut()[i].1 = orig + eps;
        let lp = loss(&render(&g, &cam, bg), &w);
        *g.scalars_mut()[i].1 = orig - eps;
        let lm = loss(&render(&g, &cam, bg), &w);
        *g.scalars_mut()[i].1 = orig;
        let fd = (lp - lm) / (2.0 * eps);
        let an = analytic[i];
        let err = (fd - an).abs() / (fd.abs().max(an.abs()) + 1e-6);
        let e = worst.entry(names[i]).or_insert((0.0, 0, 0));
        e.0 = e.0.max(err);
        e.1 += 1;
        e.2 += usize::from(an.abs() > 1e-4);
        assert!(
            err < 0.01,
            "{} #{i}: finite difference {fd} vs analytic {an}",
            names[i]
        );
    }
    // Every group must actually be exercised, not pass by being zero everywhere.
    for (name, (err, total, nonzero)) in &worst {
        eprintln!("{name}: {total} scalars, {nonzero} non-zero, worst relative error {err:.2e}");
        assert!(
            *nonzero * 2 > *total,
            "{name}: only {nonzero}/{total} gradients are non-zero"
        );
    }
    assert_eq!(worst.len(), 5);
}

#[test]
fn reference_gradients_match_finite_differences_sh3() {
    check(14, 3, 7);
}

#[test]
fn reference_gradients_match_finite_differences_sh0() {
    check(20, 0, 11);
}

#[test]
fn reference_gradients_match_finite_differences_sh1_dense() {
    // Dense enough that pixels saturate and hit early termination.
    check(40, 1, 23);
}
