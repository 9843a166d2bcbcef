//! SH growth on the GPU against its CPU model, every degree step, with rows of room past the
//! live ones (as densification leaves them).

mod common;

use cocog_train::{SplitMix64, record_widen_sh, widen_kernel, widen_sh};
use common::*;

#[test]
fn widening_on_the_gpu_matches_the_cpu_model_at_every_degree() {
    let Some(ctx) = gpu() else { return };
    let kernel = widen_kernel(ctx);
    let mut rng = SplitMix64::new(9);
    let rows = 301;
    for (old_k, new_k) in [(1u32, 4u32), (4, 9), (9, 16), (1, 16)] {
        let old: Vec<f32> = (0..rows * 3 * old_k as usize)
            .map(|_| rng.next_f64() as f32 - 0.5)
            .collect();
        let buffer = ctx.storage_from("sh", &old);
        let mut rec = ctx.recorder();
        let wide = record_widen_sh(&mut rec, &kernel, &buffer, old_k, new_k);
        rec.submit();
        let want = widen_sh(&old, old_k as usize, new_k as usize);
        assert_eq!(
            wide.size(),
            want.len() as u64 * 4,
            "{old_k} → {new_k}: room kept"
        );
        let got: Vec<f32> = ctx.read(&wide, want.len()).unwrap();
        assert_eq!(got, want, "{old_k} → {new_k}");
    }
}
