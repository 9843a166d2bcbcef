//! The GPU prefix sum and radix sort against plain CPU results on random inputs with
//! duplicates and sizes that are not multiples of the block size.

mod common;

use cocog_engine::{PrefixSum, RadixSort, SortBuffers, SortCount, Workspace};
use common::{Rng, gpu};

fn random_u32(n: usize, modulo: u32, seed: u64) -> Vec<u32> {
    let mut rng = Rng::new(seed);
    (0..n).map(|_| (rng.next_u64() as u32) % modulo).collect()
}

#[test]
fn prefix_sum_matches_cpu() {
    let Some(ctx) = gpu() else { return };
    let scan = PrefixSum::new(ctx);
    // 1, one block, a partial block, and three levels of recursion (> 1024²).
    for (i, &n) in [1usize, 7, 1024, 1025, 5000, 1_048_577 + 3]
        .iter()
        .enumerate()
    {
        let input = random_u32(n, 1000, i as u64);
        let buf = ctx.storage_from("scan input", &input);
        let mut rec = ctx.recorder();
        scan.encode(&mut rec, &mut Workspace::default(), &buf, n as u32);
        rec.submit();
        let got: Vec<u32> = ctx.read(&buf, n).unwrap();
        let mut acc = 0u32;
        for (j, (&g, &x)) in got.iter().zip(&input).enumerate() {
            assert_eq!(g, acc, "n={n}: element {j}");
            acc = acc.wrapping_add(x);
        }
    }
}

fn check_sort(n: usize, modulo: u32, bits: u32, seed: u64) {
    check_sort_of(random_u32(n, modulo, seed), bits, false);
}

/// Sorts `keys` (values: their positions) on the GPU and compares with a stable CPU sort; with
/// `drop`, keys of `u32::MAX` are dropped and the kept count must come back too.
fn check_sort_of(keys: Vec<u32>, bits: u32, drop: bool) {
    let Some(ctx) = gpu() else { return };
    let scan = PrefixSum::new(ctx);
    let sort = RadixSort::new(ctx, "test");
    let n = keys.len();
    let values: Vec<u32> = (0..n as u32).collect();
    let mut bufs = SortBuffers::new(
        ctx,
        ctx.storage_from("keys", &keys),
        ctx.storage_from("values", &values),
        n as u32,
    );
    let mut rec = ctx.recorder();
    let mut ws = Workspace::default();
    let count = SortCount::Host(n as u32);
    // Set to garbage: the sort must write it.
    let kept = ctx.storage_from("kept", &[u32::MAX - 1; 4]);
    let kept_out = drop.then_some(&kept);
    sort.encode(&mut rec, &mut ws, &scan, &mut bufs, count, bits, kept_out);
    rec.submit();
    // Stable sort on the low `bits` bits: ties keep their input order.
    let mask = if bits >= 32 {
        u32::MAX
    } else {
        (1u32 << bits) - 1
    };
    let mut expected: Vec<(u32, u32)> = keys.iter().copied().zip(values.iter().copied()).collect();
    if drop {
        expected.retain(|&(k, _)| k != u32::MAX);
        let got: Vec<u32> = ctx.read(&kept, 1).unwrap();
        assert_eq!(
            got[0] as usize,
            expected.len(),
            "n={n} bits={bits}: kept count"
        );
    }
    expected.sort_by_key(|&(k, _)| k & mask);
    let m = expected.len();
    let got_keys: Vec<u32> = ctx.read(&bufs.keys, n).unwrap();
    let got_values: Vec<u32> = ctx.read(&bufs.values, n).unwrap();
    let got: Vec<(u32, u32)> = got_keys.into_iter().zip(got_values).take(m).collect();
    for (i, (g, e)) in got.iter().zip(&expected).enumerate() {
        assert_eq!(g, e, "n={n} bits={bits} drop={drop}: position {i}");
    }
}

/// Keys where a share of them are `u32::MAX` (culled Gaussians), the rest random below
/// `modulo`.
fn with_dropped(n: usize, modulo: u32, every: u64, seed: u64) -> Vec<u32> {
    let mut rng = Rng::new(seed);
    (0..n)
        .map(|_| {
            let r = rng.next_u64();
            if r.is_multiple_of(every) {
                u32::MAX
            } else {
                ((r >> 8) as u32) % modulo
            }
        })
        .collect()
}

/// The depth sort's culling: dropped keys are set aside in the first pass and the later passes
/// sort what is left. Most dropped (as in a capture around the viewer), a few, none, all;
/// blocks left empty after the first pass, partial blocks, one pass (≤ 8 bits) and duplicates
/// among the kept keys, and keys that differ from `u32::MAX` only in the unsorted high bits
/// (kept: dropping looks at the whole key).
#[test]
fn radix_sort_drops_max_keys() {
    check_sort_of(with_dropped(50_003, u32::MAX, 3, 10), 32, true);
    check_sort_of(with_dropped(50_003, u32::MAX, 1, 11), 32, true);
    check_sort_of(with_dropped(3001, 1000, 50, 12), 32, true);
    check_sort_of(with_dropped(3001, 1000, 2, 13), 8, true);
    check_sort_of(random_u32(2049, 77, 14), 32, true);
    check_sort_of(vec![u32::MAX; 1500], 32, true);
    check_sort_of(vec![u32::MAX, 5, u32::MAX - 1, 5, 0, u32::MAX], 12, true);
    check_sort_of(vec![u32::MAX], 32, true);
    check_sort_of(vec![3], 32, true);
}

#[test]
fn radix_sort_full_keys_with_duplicates() {
    check_sort(3001, u32::MAX, 32, 1);
    check_sort(2048, 37, 32, 2);
}

/// Hundreds of blocks: digits spread over many blocks' histogram entries, a last block part
/// full; and 9 bits as a tile sort of a 400×300 frame has (475 tiles), a last pass of 1 bit.
#[test]
fn radix_sort_many_blocks() {
    check_sort(200_003, u32::MAX, 32, 6);
    check_sort(100_000, 475, 9, 7);
}

#[test]
fn radix_sort_partial_bits_is_stable() {
    // Keys above the sorted bits must not affect order, and equal low bits keep input order.
    check_sort(5003, 1 << 20, 12, 3);
    check_sort(1, 5, 4, 4);
    check_sort(17, 3, 5, 5);
}
