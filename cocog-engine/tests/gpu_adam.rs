//! The GPU Adam step against its formula evaluated in f64 over several steps.

mod common;

use cocog_engine::{Adam, AdamConfig, AdamMoments};
use common::{Rng, gpu};

#[test]
fn adam_matches_formula_over_several_steps() {
    let Some(ctx) = gpu() else { return };
    let n = 1000;
    let mut rng = Rng::new(21);
    let mut p: Vec<f64> = (0..n).map(|_| rng.range(-1.0, 1.0)).collect();
    let (mut m, mut v) = (vec![0.0f64; n], vec![0.0f64; n]);
    let config = AdamConfig {
        lr: 0.01,
        beta1: 0.9,
        beta2: 0.999,
        eps: 1e-8,
        interleaved: None,
    };
    let param = ctx.storage_from("param", &p.iter().map(|&x| x as f32).collect::<Vec<_>>());
    let moments = AdamMoments::new(ctx, n as u32);
    let adam = Adam::new(ctx);
    for t in 1..=5u32 {
        let g: Vec<f32> = (0..n).map(|_| rng.range_f32(-2.0, 2.0)).collect();
        let grad = ctx.storage_from("grad", &g);
        let mut rec = ctx.recorder();
        adam.encode(&mut rec, &param, &grad, &moments, &config, t, None);
        rec.submit();
        let (b1, b2) = (f64::from(config.beta1), f64::from(config.beta2));
        for i in 0..n {
            let gi = f64::from(g[i]);
            m[i] = b1 * m[i] + (1.0 - b1) * gi;
            v[i] = b2 * v[i] + (1.0 - b2) * gi * gi;
            let m_hat = m[i] / (1.0 - b1.powi(t as i32));
            let v_hat = v[i] / (1.0 - b2.powi(t as i32));
            p[i] -= f64::from(config.lr) * m_hat / (v_hat.sqrt() + f64::from(config.eps));
        }
        let got: Vec<f32> = ctx.read(&param, n).unwrap();
        for i in 0..n {
            assert!(
                (f64::from(got[i]) - p[i]).abs() < 1e-5,
                "step {t} element {i}: {} vs {}",
                got[i],
                p[i]
            );
        }
    }
    // The moments are state too: check the second one after the last step.
    let got_v: Vec<f32> = ctx.read(&moments.v, n).unwrap();
    for i in 0..n {
        assert!((f64::from(got_v[i]) - v[i]).abs() < 1e-6 * v[i].max(1.0));
    }
}

#[test]
fn interleaved_groups_step_at_their_own_rates() {
    let Some(ctx) = gpu() else { return };
    // Two Gaussians' SH at degree 1: 3 channels × 4 coefficients, DC first in each block.
    let n = 24;
    let grad: Vec<f32> = (0..n)
        .map(|i| if i % 3 == 0 { -0.5 } else { 0.25 })
        .collect();
    let param = ctx.storage_from("param", &vec![1.0f32; n]);
    let grad_buf = ctx.storage_from("grad", &grad);
    let moments = AdamMoments::new(ctx, n as u32);
    let mut rec = ctx.recorder();
    let config = AdamConfig::with_lr(0.01).interleaved(4, 0.0005);
    Adam::new(ctx).encode(&mut rec, &param, &grad_buf, &moments, &config, 1, None);
    rec.submit();
    let out: Vec<f32> = ctx.read(&param, n).unwrap();
    for (i, (p, g)) in out.iter().zip(&grad).enumerate() {
        // Adam's first step moves every element by its rate against the gradient's sign.
        let lr = if i % 4 == 0 { 0.01 } else { 0.0005 };
        let want = 1.0 - lr * g.signum();
        assert!((p - want).abs() < 1e-6, "element {i}: {p} vs {want}");
    }
}

#[test]
fn a_set_skip_flag_leaves_parameters_and_moments_untouched() {
    let Some(ctx) = gpu() else { return };
    let n = 300;
    let param = ctx.storage_from("param", &vec![1.0f32; n]);
    let grad = ctx.storage_from("grad", &vec![0.5f32; n]);
    let moments = AdamMoments::new(ctx, n as u32);
    let config = AdamConfig::with_lr(0.01);
    let adam = Adam::new(ctx);
    for (flag, moved) in [(1u32, false), (0, true)] {
        let skip = ctx.storage_from("skip", &[flag, 0]);
        let mut rec = ctx.recorder();
        adam.encode(&mut rec, &param, &grad, &moments, &config, 1, Some(&skip));
        rec.submit();
        let p: Vec<f32> = ctx.read(&param, n).unwrap();
        let m: Vec<f32> = ctx.read(&moments.m, n).unwrap();
        assert!(
            p.iter().all(|&v| (v != 1.0) == moved),
            "flag {flag}: {:?}",
            &p[..3]
        );
        assert!(
            m.iter().all(|&v| (v != 0.0) == moved),
            "flag {flag}: {:?}",
            &m[..3]
        );
    }
}
