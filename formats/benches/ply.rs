//! Writing and reading a large 3DGS PLY: the size `cocog export` and viewers meet in practice.
//!
//! `cargo bench -p cocog-formats --bench ply`; COCOG_BENCH_SPLATS [1000000] splats at SH
//! degree COCOG_BENCH_SH [3]. Prints seconds and MB/s each way and the process's peak
//! resident memory (Linux), to compare with the file size: the reader should not need
//! several copies of the file in memory.

use std::time::Instant;

use cocog_formats::ply::{read_splats, write_splats};
use cocog_formats::rng::SplitMix64;
use cocog_formats::splats::{Splats, sh_rest_per_channel};

fn env(name: &str, default: u64) -> u64 {
    std::env::var(name)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

/// Peak resident memory of this process in MiB (`VmHWM`), where the OS reports it.
fn peak_rss_mib() -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kib: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib / 1024.0)
}

fn main() {
    let n = env("COCOG_BENCH_SPLATS", 1_000_000) as usize;
    let degree = env("COCOG_BENCH_SH", 3) as u32;
    // Any finite numbers do: the format does not care.
    let mut rng = SplitMix64::new(1);
    let mut v = |k: usize| {
        (0..k)
            .map(|_| (rng.next_f64() * 4.0 - 2.0) as f32)
            .collect::<Vec<f32>>()
    };
    let splats = Splats {
        means: v(3 * n),
        log_scales: v(3 * n),
        rotations: v(4 * n),
        opacities: v(n),
        sh_dc: v(3 * n),
        sh_rest: v(3 * sh_rest_per_channel(degree) * n),
        sh_degree: degree,
    };
    let in_memory = peak_rss_mib();
    let dir = std::env::temp_dir().join(format!("cocog-ply-bench-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let path = dir.join("splats.ply");
    let t = Instant::now();
    write_splats(&path, &splats, None).expect("write");
    let write = t.elapsed().as_secs_f64();
    let mb = std::fs::metadata(&path).expect("written").len() as f64 / 1e6;
    drop(splats);
    let t = Instant::now();
    let back = read_splats(&path).expect("read");
    let read = t.elapsed().as_secs_f64();
    assert_eq!(back.len(), n);
    let _ = std::fs::remove_dir_all(&dir);
    println!(
        "{n} splats, SH degree {degree}, {mb:.0} MB: write {write:.2} s ({:.0} MB/s), \
         read {read:.2} s ({:.0} MB/s)",
        mb / write,
        mb / read
    );
    if let (Some(base), Some(peak)) = (in_memory, peak_rss_mib()) {
        println!("peak resident memory {peak:.0} MiB (the splats in memory alone: {base:.0} MiB)");
    }
}
