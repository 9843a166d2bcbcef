//! LPIPS against the recorded reference values (which agree with the official PyTorch package to
//! 4 decimals). Needs the converted weights (scripts/lpips/fetch-weights.sh).

mod common;

use std::path::Path;

use cocog_metrics::{Lpips, MetricsError, Net, load_image};

const TOL: f64 = 1e-4;

/// `pairs_limit` bounds the work: VGG costs ~25× AlexNet, so its test scores fewer pairs.
fn check(net: Net, key: &str, test: &str, pairs_limit: usize) {
    let Some(shared) = common::shared_dir() else {
        return common::skip(test, "../shared/metrics-ref not found");
    };
    let model = match Lpips::load(net) {
        Ok(m) => m,
        Err(e @ MetricsError::WeightsNotFound { .. }) => return common::skip(test, &e.to_string()),
        Err(e) => panic!("{e}"),
    };
    let dir = shared.join("metrics-ref");
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("reference.json")).unwrap())
            .unwrap();
    let mut worst: f64 = 0.0;
    for pair in json["pairs"].as_array().unwrap().iter().take(pairs_limit) {
        let load = |k: &str| load_image(&dir.join(Path::new(pair[k].as_str().unwrap()))).unwrap();
        let (a, b) = (load("a"), load("b"));
        let want = pair[key].as_f64().unwrap();
        let got = model
            .distance(&a, &b)
            .expect("reference images fit the net");
        // LPIPS is symmetric; checking both orders catches a swapped normalisation.
        let back = if net == Net::Alex {
            model.distance(&b, &a).unwrap()
        } else {
            got
        };
        assert!(
            (got - want).abs() < TOL && (back - want).abs() < TOL,
            "{key} {} / {}: got {got} (reversed {back}), reference {want}",
            pair["a"],
            pair["b"]
        );
        worst = worst.max((got - want).abs());
    }
    eprintln!("{key}: worst deviation from reference {worst:.2e}");
}

#[test]
fn lpips_alex_reproduces_reference_values() {
    check(
        Net::Alex,
        "lpips_alex",
        "lpips_alex_reproduces_reference_values",
        usize::MAX,
    );
}

#[test]
fn lpips_vgg_reproduces_reference_values() {
    // The three 64-px pairs and one 512×384 calibration pair.
    check(
        Net::Vgg,
        "lpips_vgg",
        "lpips_vgg_reproduces_reference_values",
        4,
    );
}

#[test]
fn corrupt_or_mismatched_weights_are_refused_with_the_file_name() {
    let dir = tempfile::tempdir().unwrap();
    let junk = dir.path().join("alex.safetensors");
    std::fs::write(&junk, b"definitely not safetensors").unwrap();
    let err = Lpips::from_file(&junk, Net::Alex)
        .err()
        .unwrap()
        .to_string();
    assert!(
        err.contains("alex.safetensors") && err.contains("bad LPIPS weights"),
        "{err}"
    );

    // A real AlexNet file offered as VGG must be refused by its metadata, not mis-run.
    if let Ok(alex) = cocog_metrics::find_weights(Net::Alex) {
        let err = Lpips::from_file(&alex, Net::Vgg).err().unwrap().to_string();
        assert!(err.contains("expected \"vgg\""), "{err}");
    }
}
