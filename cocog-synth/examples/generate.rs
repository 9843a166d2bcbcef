//! Writes the default synthetic defocus dataset: `cargo run -p cocog-synth --example generate -- DIR [SEED]`.

use std::path::PathBuf;
use std::process::ExitCode;

use cocog_synth::{SynthConfig, write_defocus_dataset};

fn main() -> ExitCode {
    let mut args = std::env::args().skip(1);
    let Some(dir) = args.next().map(PathBuf::from) else {
        eprintln!("usage: generate DIR [SEED]");
        return ExitCode::from(2);
    };
    let seed = match args.next().map(|s| s.parse::<u64>()) {
        None => 0,
        Some(Ok(s)) => s,
        Some(Err(e)) => {
            eprintln!("SEED: {e}");
            return ExitCode::from(2);
        }
    };
    let cfg = SynthConfig {
        seed,
        ..SynthConfig::default()
    };
    match write_defocus_dataset(&dir, &cfg) {
        Ok(s) => {
            println!(
                "{}: {} views ({} train, {} test) {}x{}, {} Gaussians, {} points, {:.2} s",
                s.dir.display(),
                s.views,
                s.train_views,
                s.test_views,
                s.width,
                s.height,
                s.gaussians,
                s.points,
                s.elapsed.as_secs_f64()
            );
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}
