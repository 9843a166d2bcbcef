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
    };
    let param = ctx.storage_from("param", &p.iter().map(|&x| x as f32).collect::<Vec<_>>());
    let moments = AdamMoments::new(ctx, n as u32);
    let adam = Adam::new(ctx);
    for t in 1..=5u32 {
        let g: Vec<f32> = (0..n).map(|_| rng.range_f32(-2.0, 2.0)).collect();
        let grad = ctx.storage_from("grad", &g);
        let mut enc = ctx.device.create_command_encoder(&Default::default());
        adam.encode(ctx, &mut enc, &param, &grad, &moments, &config, t);
        ctx.queue.submit([enc.finish()]);
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
