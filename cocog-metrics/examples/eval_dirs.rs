//! Scores a predictions folder against a ground-truth folder and prints the table and the wall
//! time: `cargo run --release -p cocog-metrics --example eval_dirs -- PRED GT [THREADS]`.

use std::time::Instant;

use cocog_metrics::{EvalOptions, evaluate_dirs, format_table};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [pred, gt, rest @ ..] = args.as_slice() else {
        return Err("usage: eval_dirs PRED GT [THREADS]".into());
    };
    let opts = EvalOptions {
        threads: rest.first().map(|t| t.parse()).transpose()?.unwrap_or(0),
        ..EvalOptions::default()
    };
    let start = Instant::now();
    let report = evaluate_dirs(pred.as_ref(), gt.as_ref(), &opts, &())?;
    let elapsed = start.elapsed().as_secs_f64();
    print!("{}", format_table(&report.to_json()));
    println!("{} image pair(s) in {elapsed:.3} s", report.count);
    Ok(())
}
