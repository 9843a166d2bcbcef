//! Times LPIPS forward passes on one image pair: `cargo run --release --example lpips_timing -p
//! cocog-metrics -- A.png B.png [alex|vgg] [threads]`.

use std::time::Instant;

use cocog_metrics::{Lpips, Net, load_image};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [a, b, rest @ ..] = args.as_slice() else {
        return Err("usage: lpips_timing A.png B.png [alex|vgg] [threads]".into());
    };
    let net = match rest.first().map(String::as_str) {
        None | Some("alex") => Net::Alex,
        Some("vgg") => Net::Vgg,
        Some(other) => return Err(format!("unknown net {other:?}").into()),
    };
    let threads = rest.get(1).map(|t| t.parse()).transpose()?.unwrap_or(0);
    let model = Lpips::load(net)?.with_threads(threads);
    let (x, y) = (load_image(a.as_ref())?, load_image(b.as_ref())?);
    for _ in 0..3 {
        let t = Instant::now();
        let d = model.distance(&x, &y).ok_or("image too small")?;
        println!(
            "{} {d:.6} in {:.3} s",
            net.name(),
            t.elapsed().as_secs_f64()
        );
    }
    Ok(())
}
