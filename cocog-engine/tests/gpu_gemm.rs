//! The tiled matrix product against an f64 product, for every operand layout, with and
//! without split K, at sizes that leave partial tiles on every edge.

mod common;

use cocog_engine::{Gemm, GemmLayout, GemmShape, GemmTile};
use common::{Rng, gpu, plain_gemm_problem, run_gemm};

/// The epilogue's offset (0.5) proves it runs once per value, after any split reduction.
const OFFSET: f32 = 0.5;

fn check(layout: GemmLayout, m: usize, n: usize, k: usize, batches: usize, seed: u64) {
    let Some(ctx) = gpu() else { return };
    let mut rng = Rng::new(seed);
    let a: Vec<f32> = (0..batches * m * k)
        .map(|_| rng.range_f32(-1.0, 1.0))
        .collect();
    let mut b: Vec<f32> = (0..batches * k * n)
        .map(|_| rng.range_f32(-1.0, 1.0))
        .collect();
    // A ones column is never loaded: what the buffer holds there must not reach C.
    let ones = layout.ones_column.then_some(n - 1);
    let at = |bt: usize, i: usize, kk: usize| {
        f64::from(if layout.a_k_fast {
            a[(bt * m + i) * k + kk]
        } else {
            a[(bt * k + kk) * m + i]
        })
    };
    let b_at = |bt: usize, kk: usize, j: usize| {
        if layout.b_k_fast {
            (bt * n + j) * k + kk
        } else {
            (bt * k + kk) * n + j
        }
    };
    if let Some(j) = ones {
        for bt in 0..batches {
            for kk in 0..k {
                b[b_at(bt, kk, j)] = 7.0;
            }
        }
    }
    let bt_ = |bt: usize, kk: usize, j: usize| {
        if Some(j) == ones {
            return 1.0;
        }
        f64::from(b[b_at(bt, kk, j)])
    };
    let gemm = Gemm::new(
        ctx,
        "test gemm",
        &plain_gemm_problem(layout, OFFSET),
        layout,
    );
    let outputs = if layout.split_k { 1 } else { batches };
    let shape = GemmShape {
        m: m as u32,
        n: n as u32,
        k: k as u32,
        batches: batches as u32,
        ..Default::default()
    };
    let got = run_gemm(ctx, &gemm, shape, &a, &b, outputs);
    for o in 0..outputs {
        let summed: Vec<usize> = if layout.split_k {
            (0..batches).collect()
        } else {
            vec![o]
        };
        for i in 0..m {
            for j in 0..n {
                let (mut want, mut mag) = (0.5, 0.0);
                for &bt in &summed {
                    for kk in 0..k {
                        want += at(bt, i, kk) * bt_(bt, kk, j);
                        mag += (at(bt, i, kk) * bt_(bt, kk, j)).abs();
                    }
                }
                let g = f64::from(got[(o * m + i) * n + j]);
                // f32 accumulation: error grows with the sum of magnitudes.
                let tol = 1e-6 * mag + 1e-6;
                assert!(
                    (g - want).abs() <= tol,
                    "{layout:?} {batches}×{m}×{n}×{k}: C[{o}][{i}][{j}] = {g}, want {want} (±{tol})"
                );
            }
        }
    }
}

const TILES: [GemmTile; 4] = [
    GemmTile::SQUARE,
    GemmTile::new(2, 128),
    GemmTile::new(4, 16),
    GemmTile::new(16, 4),
];

#[test]
fn every_layout_and_tile_matches_f64() {
    for tile in TILES {
        for a_k_fast in [false, true] {
            for b_k_fast in [false, true] {
                let layout = GemmLayout {
                    a_k_fast,
                    b_k_fast,
                    split_k: false,
                    ones_column: false,
                    tile,
                };
                check(layout, 70, 45, 37, 1, 1);
                check(layout, 1, 130, 9, 1, 2);
                // Batches are independent products (grid z).
                check(layout, 9, 600, 20, 3, 3);
            }
        }
    }
}

#[test]
fn split_k_sums_every_range_and_batch_once() {
    for tile in TILES {
        for (a_k_fast, b_k_fast) in [(false, true), (true, false)] {
            let layout = GemmLayout {
                a_k_fast,
                b_k_fast,
                split_k: true,
                ones_column: false,
                tile,
            };
            // K far beyond one part, and not a multiple of the tile depth.
            check(layout, 64, 77, 5003, 1, 4);
            check(layout, 3, 10, 777, 1, 5);
            // Batches summed as well (a weight gradient over several images).
            check(layout, 16, 30, 1000, 4, 6);
            // Slices (batches × parts) not a multiple of the reduce's four running sums: 3
            // batches of K = 600 (at most three parts each), and one batch of 5 parts.
            check(layout, 8, 12, 600, 3, 7);
            check(layout, 64, 77, 1300, 1, 8);
        }
    }
}

/// A bias's gradient: B's last column is ones, summed on the side by the first column of tiles.
/// The shapes put that column just past a full tile (N = 65: one tile, not two), inside a
/// partial one, and alone beside a single column; K spans several parts and batches.
#[test]
fn a_ones_column_is_the_row_sums() {
    for tile in TILES {
        for (a_k_fast, b_k_fast) in [(false, false), (true, true)] {
            for split_k in [false, true] {
                let layout = GemmLayout {
                    a_k_fast,
                    b_k_fast,
                    split_k,
                    ones_column: true,
                    tile,
                };
                check(layout, 64, 65, 1300, 1, 9);
                check(layout, 70, 92, 300, 2, 10);
                check(layout, 5, 2, 777, 1, 11);
            }
        }
    }
}

#[test]
fn tiles_suit_their_shapes() {
    // Long products over 64 outputs stay square; narrow ones go wide; small ones small.
    assert_eq!(GemmTile::for_shape(100_000, 64), GemmTile::SQUARE);
    assert_eq!(GemmTile::for_shape(8, 1 << 16), GemmTile::new(2, 128));
    assert_eq!(GemmTile::for_shape(16, 76), GemmTile::new(4, 16));
}
