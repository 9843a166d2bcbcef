//! The tile spans (tile_test.wgsl's `row_span`) that project.wgsl counts and tiles.wgsl emits:
//! on rows of every width, for round and needle-thin, faint and opaque Gaussians, each row's
//! span must be exactly the one a scan of every tile with `tile_hits` finds, the walk from a
//! seed must reach it from any guess of its ends, the guesses from the ellipse's extent must
//! nearly always be the ends already (else the walks cost what the scan did), and every tile
//! whose rectangle an f64 search clearly finds reached (or clearly not) must lie inside (or
//! outside) it.

mod common;

use cocog_engine::splat::FINITE_WGSL;
use cocog_engine::{Kernel, shader};
use common::{Rng, gpu};

/// One row of one Gaussian: mean, conic (a, b, c) and threshold ln(255·opacity), the row and
/// its rectangle's columns, and two guesses of the span's ends for the walk.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Case {
    mean: [f32; 2],
    pad: [f32; 2],
    form: [f32; 4],
    row: [u32; 4],
    guesses: [u32; 4],
}

const KERNEL: &str = "
struct Case { mean: vec2<f32>, pad: vec2<f32>, form: vec4<f32>, row: vec4<u32>, guesses: vec4<u32> }
@group(0) @binding(0) var<storage, read> cases: array<Case>;
// Per case: (scan first, scan end, span first, span end), (walk first, walk end, tiles hit,
// seed), (guessed first, guessed last).
@group(0) @binding(1) var<storage, read_write> out: array<vec4<u32>>;

@compute @workgroup_size(64)
fn spans(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = gid.x;
    if (i >= arrayLength(&cases)) {
        return;
    }
    let k = cases[i];
    let conic = k.form.xyz;
    let thr = k.form.w;
    let ty = k.row.x;
    let lo_x = k.row.y;
    let hi_x = k.row.z;
    var first = hi_x;
    var end = hi_x;
    var hits = 0u;
    for (var x = lo_x; x < hi_x; x++) {
        if (tile_hits(k.mean, conic, thr, vec2<u32>(x, ty))) {
            first = min(first, x);
            end = x + 1u;
            hits++;
        }
    }
    let span = row_span(k.mean, conic, thr, ty, lo_x, hi_x);
    let seed = span_seed(k.mean, conic, thr, ty, lo_x, hi_x);
    var walked = vec2<u32>(0u, 0u);
    var guess = vec2<u32>(0u, 0u);
    if (seed != NO_SEED) {
        walked = walk_span(k.mean, conic, thr, ty, lo_x, hi_x, seed, k.guesses.x, k.guesses.y);
        guess = span_guess(k.mean, conic, thr, ty, lo_x, hi_x, seed);
    }
    out[3u * i] = vec4<u32>(first, end, span.x, span.y);
    out[3u * i + 1u] = vec4<u32>(walked.x, walked.y, hits, seed);
    out[3u * i + 2u] = vec4<u32>(guess, 0u, 0u);
}
";

const NO_SEED: u32 = u32::MAX;
const TILES: (u32, u32) = (48, 32);

/// Rows of random Gaussians in a 768×512 frame (48 × 32 tiles): σ from half a pixel to 300
/// pixels, up to 1000:1, any angle, opacity from just over 1/255 to 1; the rectangle the
/// projection gives (3σ of the larger axis, clamped to the frame), every row of it.
fn cases(rng: &mut Rng, gaussians: usize) -> Vec<Case> {
    let mut out = Vec::new();
    for _ in 0..gaussians {
        let mean = [
            rng.range(-100.0, 868.0) as f32,
            rng.range(-100.0, 612.0) as f32,
        ];
        let s1 = 10f64.powf(rng.range(-0.3, 2.5));
        let s2 = s1 * 10f64.powf(-rng.range(0.0, 3.0));
        let th = rng.range(0.0, std::f64::consts::PI);
        let (sn, cs) = th.sin_cos();
        // Σ = R diag(s1², s2²) Rᵀ plus the projection's low-pass 0.3, as f32 as the GPU has it.
        let xx = cs * cs * s1 * s1 + sn * sn * s2 * s2 + 0.3;
        let xy = cs * sn * (s1 * s1 - s2 * s2);
        let yy = sn * sn * s1 * s1 + cs * cs * s2 * s2 + 0.3;
        let det = xx * yy - xy * xy;
        let form = [
            (yy / det) as f32,
            (-xy / det) as f32,
            (xx / det) as f32,
            (255.0 * rng.range(1.0 / 250.0, 1.0)).ln() as f32,
        ];
        let mid = 0.5 * (xx + yy);
        let radius = (3.0 * (mid + (mid * mid - det).max(0.1).sqrt()).sqrt()).ceil();
        let lo = |m: f32, n: u32| {
            ((f64::from(m) - radius) / 16.0)
                .floor()
                .clamp(0.0, n as f64) as u32
        };
        let hi =
            |m: f32, n: u32| ((f64::from(m) + radius) / 16.0).ceil().clamp(0.0, n as f64) as u32;
        let (x0, x1) = (lo(mean[0], TILES.0), hi(mean[0], TILES.0));
        for ty in lo(mean[1], TILES.1)..hi(mean[1], TILES.1) {
            if x0 >= x1 {
                break;
            }
            let guess = |rng: &mut Rng| x0 + (rng.next_u64() % u64::from(x1 - x0)) as u32;
            out.push(Case {
                mean,
                pad: [0.0; 2],
                form,
                row: [ty, x0, x1, 0],
                guesses: [guess(rng), guess(rng), 0, 0],
            });
        }
    }
    out
}

/// Vertical needles (σx ≈ 0, σy 100 pixels, opacity 0.01) whose mean lies in the one-pixel gap
/// between two columns' pixel centres, 0.1 pixel before the next column's first: the band's
/// least x falls in the column before, which the Gaussian misses, and only the next one is hit.
fn gap_cases() -> Vec<Case> {
    let (xx, yy) = (0.01f64 * 0.01 + 0.3, 100.0f64 * 100.0 + 0.3);
    let form = [
        (1.0 / xx) as f32,
        0.0,
        (1.0 / yy) as f32,
        (255.0f64 * 0.01).ln() as f32,
    ];
    (3..40)
        .flat_map(|k| {
            let mean = [16.0 * k as f32 + 0.4, 16.0 * (k % 20) as f32 + 8.0];
            (0..TILES.1).map(move |ty| Case {
                mean,
                pad: [0.0; 2],
                form,
                row: [ty, k - 3, k + 5, 0],
                guesses: [k - 3, k + 4, 0, 0],
            })
        })
        .collect()
}

/// ½·(the least form over tile (tx, row)'s rectangle of pixel-centre offsets), in f64: zero
/// where it holds the mean, else the least over its four edges (the form is convex), each found
/// by ternary search rather than in closed form as tile_hits does.
fn least_half_form(k: &Case, tx: u32) -> f64 {
    let [a, b, c, _] = k.form.map(f64::from);
    let q = |dx: f64, dy: f64| 0.5 * (a * dx * dx + 2.0 * b * dx * dy + c * dy * dy);
    let x0 = f64::from(tx * 16) + 0.5 - f64::from(k.mean[0]);
    let y0 = f64::from(k.row[0] * 16) + 0.5 - f64::from(k.mean[1]);
    let (x1, y1) = (x0 + 15.0, y0 + 15.0);
    if x0 <= 0.0 && x1 >= 0.0 && y0 <= 0.0 && y1 >= 0.0 {
        return 0.0;
    }
    let least_on = |f: &dyn Fn(f64) -> f64, mut lo: f64, mut hi: f64| {
        for _ in 0..200 {
            let (m1, m2) = (lo + (hi - lo) / 3.0, hi - (hi - lo) / 3.0);
            if f(m1) <= f(m2) {
                hi = m2;
            } else {
                lo = m1;
            }
        }
        f(0.5 * (lo + hi))
    };
    [
        least_on(&|x| q(x, y0), x0, x1),
        least_on(&|x| q(x, y1), x0, x1),
        least_on(&|y| q(x0, y), y0, y1),
        least_on(&|y| q(x1, y), y0, y1),
    ]
    .into_iter()
    .fold(f64::INFINITY, f64::min)
}

#[test]
fn row_spans_are_the_tiles_a_full_scan_passes() {
    let Some(ctx) = gpu() else { return };
    // Rows up to 4 tiles wide scanned (the renderer scans up to 8), so more rows are spans.
    let source = format!(
        "const SCAN_WIDTH: u32 = 4u;\n{FINITE_WGSL}\n{}\n{KERNEL}",
        include_str!("../src/splat/tile_test.wgsl")
    );
    let kernel = Kernel::new(ctx, &shader(ctx, "tile spans test", &source), "spans");
    let mut rng = Rng::new(17);
    let mut cases = cases(&mut rng, 600);
    let gaps = gap_cases();
    cases.extend(&gaps);
    let n = cases.len();
    let input = ctx.storage_from("cases", &cases);
    let output = ctx.storage("spans", (n * 48) as u64);
    let mut rec = ctx.recorder();
    kernel.dispatch_1d(
        &mut rec,
        &[(0, &input), (1, &output)],
        n.div_ceil(64) as u32,
    );
    rec.submit();
    let got: Vec<[u32; 4]> = ctx
        .read::<u32>(&output, n * 12)
        .unwrap()
        .chunks(4)
        .map(|c| [c[0], c[1], c[2], c[3]])
        .collect();

    let (mut wide, mut walked_far, mut reached, mut guessed, mut missed) = (0, 0, 0, 0, 0);
    let mut seeded_past_gap = 0;
    for (i, k) in cases.iter().enumerate() {
        let [scan_first, scan_end, first, end] = got[3 * i];
        let [walk_first, walk_end, hits, seed] = got[3 * i + 1];
        let [guess_first, guess_last, ..] = got[3 * i + 2];
        let what = format!("case {i}: {:?} {:?} {:?}", k.mean, k.form, k.row);
        let empty = scan_first == scan_end;
        // No gap inside a row: the scan's hits fill its first-to-last range.
        assert_eq!(hits, scan_end - scan_first, "{what}: hits not contiguous");
        if empty {
            assert_eq!(
                first, end,
                "{what}: span {first}..{end} where no tile passes"
            );
            assert_eq!(seed, NO_SEED, "{what}: seed {seed} where no tile passes");
        } else {
            assert_eq!((first, end), (scan_first, scan_end), "{what}: span");
            assert!(
                seed >= scan_first && seed < scan_end,
                "{what}: seed {seed} outside {scan_first}..{scan_end}"
            );
            assert_eq!(
                (walk_first, walk_end),
                (scan_first, scan_end),
                "{what}: walk"
            );
            if k.row[2] - k.row[1] > 4 {
                guessed += 1;
                missed += usize::from((guess_first, guess_last + 1) != (scan_first, scan_end));
            }
            // The gap cases' seed: the column after the gap, k = row[1] + 3.
            seeded_past_gap += usize::from(i >= n - gaps.len() && seed == k.row[1] + 3);
            let g = k.guesses;
            walked_far += usize::from(g[0].abs_diff(scan_first) > 2 || g[1].abs_diff(scan_end) > 3);
        }
        wide += usize::from(k.row[2] - k.row[1] > 4 && !empty);
        // Against f64: every tile clearly reached is in the span, every tile clearly not
        // reached outside it (tile_hits' margin is 1e-3 of the threshold).
        let thr = f64::from(k.form[3]);
        for tx in k.row[1]..k.row[2] {
            let q = least_half_form(k, tx);
            let inside = tx >= first && tx < end;
            if q <= thr * (1.0 - 1e-4) - 1e-4 {
                assert!(
                    inside,
                    "{what}: tile {tx} reached (½q {q} ≤ {thr}) but not in the span"
                );
                reached += 1;
            } else if q > thr + 2e-3 * (1.0 + thr) {
                assert!(
                    !inside,
                    "{what}: tile {tx} not reached (½q {q} > {thr}) but in the span"
                );
            }
        }
    }
    eprintln!(
        "{n} rows: {wide} spans in rows wider than 4 tiles ({missed} of their guesses off), \
         {walked_far} walked from far guesses, {reached} tiles reached"
    );
    assert!(
        wide > 500 && walked_far > 500 && reached > 5000,
        "too few telling cases"
    );
    assert!(
        seeded_past_gap > 100,
        "only {seeded_past_gap} rows seeded past a gap"
    );
    assert!(
        missed * 100 <= guessed,
        "{missed} of {guessed} wide rows' guessed ends off"
    );
}
