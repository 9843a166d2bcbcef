//! Matrix products at the shape of F's widest layer: the 3×3 64→64 convolution's forward as a
//! plain GEMM (M = 64 output channels, K = 576 = 64 inputs × 9 taps, N = pixels of every render),
//! on the f32 tiled product `Gemm` and, where the adapter has tensor cores and
//! `COCOG_COOPERATIVE_MATRIX=1` enables them, the same product on cooperative matrices
//! (`Gemm::cooperative`, f16 operands) in every block layout `COCOG_COOP_BLOCK` names; their
//! largest difference from the f32 product is printed beside the GFLOP/s.
//!
//! `cargo bench -p cocog-engine --bench gemm`; COCOG_BENCH_PIXELS [45056: six renders at 100×75,
//! rounded up to 64; 400×300 is 720000], COCOG_BENCH_ITERS [20]. COCOG_ADAPTER picks the adapter.

use std::time::Instant;

mod common;

use cocog_engine::{
    CoopBlock, Gemm, GemmLayout, GemmShape, GemmTile, GpuContext, OperandScales, Recorder,
    Workspace,
};
use common::{env, noise};

const M: u32 = 64;
const K: u32 = 576;

/// Seconds per call of `record` (after one untimed call), over `iters` calls in one submission.
fn time(ctx: &GpuContext, iters: u64, mut record: impl FnMut(&mut Recorder)) -> f64 {
    let mut rec = ctx.recorder();
    record(&mut rec);
    rec.submit();
    ctx.wait().expect("wait");
    let t = Instant::now();
    let mut rec = ctx.recorder();
    for _ in 0..iters {
        record(&mut rec);
    }
    rec.submit();
    ctx.wait().expect("wait");
    t.elapsed().as_secs_f64() / iters as f64
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let n = (env("COCOG_BENCH_PIXELS", 45_056) as u32).next_multiple_of(64);
    let iters = env("COCOG_BENCH_ITERS", 20).max(1);
    let ctx = GpuContext::new()?;
    println!("adapter: {}", ctx.adapter_name());
    println!("tensor cores: {}", ctx.cooperative_matrix_shapes());
    let mut s = 1;
    // f16-representable values, so both products see the same inputs.
    let round = |v: f32| half::f16::from_f32(v).to_f32();
    let a: Vec<f32> = (0..M * K).map(|_| round(noise(&mut s) - 0.5)).collect();
    let b: Vec<f32> = (0..K as u64 * u64::from(n))
        .map(|_| round(noise(&mut s) - 0.5))
        .collect();
    let flop = 2.0 * f64::from(M) * f64::from(K) * f64::from(n);
    println!("problem: {M}×{n}×{K} ({:.2} GFLOP)", flop / 1e9);

    let problem = "@group(0) @binding(2) var<storage, read> a: array<f32>;\n\
         @group(0) @binding(3) var<storage, read> b: array<f32>;\n\
         @group(0) @binding(4) var<storage, read_write> c: array<f32>;\n\
         fn load_a(bt: u32, m: u32, k: u32) -> f32 { return a[m * gemm.k + k]; }\n\
         fn load_b(bt: u32, k: u32, n: u32) -> f32 { return b[k * gemm.n + n]; }\n\
         fn epilogue(bt: u32, m: u32, n: u32, v: f32) { c[m * gemm.n + n] = v; }\n";
    let layout = GemmLayout {
        a_k_fast: true,
        b_k_fast: false,
        split_k: false,
        ones_column: false,
        tile: GemmTile::for_shape(M, n),
    };
    let gemm = Gemm::new(&ctx, "bench gemm", problem, layout);
    let (ga, gb) = (ctx.storage_from("a", &a), ctx.storage_from("b", &b));
    let gc = ctx.storage("c", u64::from(M) * u64::from(n) * 4);
    let mut ws = Workspace::default();
    let shape = GemmShape {
        m: M,
        n,
        k: K,
        ..Default::default()
    };
    let simt = time(&ctx, iters, |rec| {
        gemm.encode(rec, &mut ws, shape, &[(2, &ga), (3, &gb), (4, &gc)]);
    });
    println!(
        "f32 tiled product:      {:8.3} ms  {:8.0} GFLOP/s",
        1e3 * simt,
        flop / simt / 1e9
    );
    let reference: Vec<f32> = ctx.read(&gc, (M * n) as usize)?;

    let Some(fragments) = ctx.cooperative else {
        println!(
            "cooperative product:    not run (COCOG_COOPERATIVE_MATRIX=1 on an adapter with 16×16×16 or 8×8×8 f16→f32)"
        );
        return Ok(());
    };
    // Every block layout, so one run on a GPU says which to make the default.
    for (name, block) in CoopBlock::NAMED {
        if !Gemm::fits(&ctx, block, fragments) {
            println!("cooperative, block {name:5}: does not fit this adapter ({block:?})");
            continue;
        }
        let coop = Gemm::cooperative_with(
            &ctx,
            "bench coop",
            problem,
            layout,
            OperandScales::NONE,
            block,
        )
        .expect("cooperative matrices enabled");
        let hc = ctx.storage("c coop", u64::from(M) * u64::from(n) * 4);
        let tensor = time(&ctx, iters, |rec| {
            coop.encode(rec, &mut ws, shape, &[(2, &ga), (3, &gb), (4, &hc)]);
        });
        let got: Vec<f32> = ctx.read(&hc, (M * n) as usize)?;
        let worst = got
            .iter()
            .zip(&reference)
            .map(|(g, r)| (g - r).abs())
            .fold(0.0f32, f32::max);
        println!(
            "cooperative, block {name:5}: {:8.3} ms  {:8.0} GFLOP/s  ({:.1}× the f32 product; largest difference {worst:.2e})",
            1e3 * tensor,
            flop / tensor / 1e9,
            simt / tensor
        );
    }
    Ok(())
}
