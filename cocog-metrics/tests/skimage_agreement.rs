//! PSNR and both SSIM conventions against scikit-image itself, and against the recorded reference
//! values, on the real images in shared/.

mod common;

use std::path::{Path, PathBuf};

use cocog_metrics::{SsimConvention, load_image, psnr, ssim};

const TOL: f64 = 1e-6;

/// The Deblur-NeRF metrics, computed by scikit-image on images decoded by PIL.
const SKIMAGE: &str = r#"
import json, sys
import numpy as np
from PIL import Image
from skimage.metrics import structural_similarity, peak_signal_noise_ratio
def load(p):
    return np.asarray(Image.open(p).convert("RGB"), dtype=np.float64) / 255.0
out = []
for a, b in zip(sys.argv[1::2], sys.argv[2::2]):
    x, y = load(a), load(b)
    out.append([
        peak_signal_noise_ratio(x, y, data_range=1.0),
        structural_similarity(2 * x - 1, 2 * y - 1, channel_axis=-1, data_range=2.0),
        structural_similarity(x, y, channel_axis=-1, data_range=1.0, gaussian_weights=True,
                              sigma=1.5, use_sample_covariance=False),
    ])
print(json.dumps(out))
"#;

fn rust_metrics(a: &Path, b: &Path) -> [f64; 3] {
    let (x, y) = (load_image(a).unwrap(), load_image(b).unwrap());
    [
        psnr(&x, &y),
        ssim(&x, &y, SsimConvention::DeblurNerf).unwrap(),
        ssim(&x, &y, SsimConvention::Gaussian11).unwrap(),
    ]
}

/// Pairs of real images of different character: sharp vs defocused (the do-nothing baseline),
/// defocused vs defocused of a neighbouring pose, sharp vs sharp, and the LPIPS/IQA test images.
fn bench_pairs(shared: &Path) -> Vec<(PathBuf, PathBuf)> {
    let mut pairs = Vec::new();
    for scene in ["defocus-dev/dev-table", "defocus-dev/dev-shelf"] {
        let s = shared.join("bench").join(scene);
        for v in ["000", "008", "016"] {
            pairs.push((
                s.join(format!("images/{v}.png")),
                s.join(format!("baseline/{v}.png")),
            ));
        }
        pairs.push((s.join("images/001.png"), s.join("images/002.png")));
    }
    let sharp = shared.join("bench/sharp-dev/images");
    pairs.push((sharp.join("000.png"), sharp.join("001.png")));
    pairs.extend(reference_pairs(shared).into_iter().map(|(a, b, _)| (a, b)));
    pairs
}

fn reference_pairs(shared: &Path) -> Vec<(PathBuf, PathBuf, serde_json::Value)> {
    let dir = shared.join("metrics-ref");
    let text = std::fs::read_to_string(dir.join("reference.json")).unwrap();
    let json: serde_json::Value = serde_json::from_str(&text).unwrap();
    json["pairs"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| {
            let a = dir.join(p["a"].as_str().unwrap());
            let b = dir.join(p["b"].as_str().unwrap());
            (a, b, p.clone())
        })
        .collect()
}

#[test]
fn psnr_and_ssim_match_scikit_image() {
    let name = "psnr_and_ssim_match_scikit_image";
    let Some(shared) = common::shared_dir() else {
        return common::skip(name, "../shared (bench images) not found");
    };
    let pairs = bench_pairs(&shared);
    let args: Vec<String> = pairs
        .iter()
        .flat_map(|(a, b)| [a.display().to_string(), b.display().to_string()])
        .collect();
    let stdout = match common::python(SKIMAGE, &args) {
        Ok(s) => s,
        Err(reason) => return common::skip(name, &reason),
    };
    let want: Vec<[f64; 3]> = serde_json::from_str(stdout.trim()).unwrap();
    assert_eq!(want.len(), pairs.len());
    let mut worst = [0.0f64; 3];
    for ((a, b), want) in pairs.iter().zip(&want) {
        let got = rust_metrics(a, b);
        for i in 0..3 {
            worst[i] = worst[i].max((got[i] - want[i]).abs());
        }
        for (i, metric) in ["psnr", "ssim_deblurnerf", "ssim_gaussian11"]
            .iter()
            .enumerate()
        {
            assert!(
                (got[i] - want[i]).abs() < TOL,
                "{metric} {} vs {}: rust {} skimage {}",
                a.display(),
                b.display(),
                got[i],
                want[i]
            );
        }
    }
    eprintln!(
        "{} pairs; worst |rust - skimage|: psnr {:.1e}, ssim_deblurnerf {:.1e}, ssim_gaussian11 {:.1e}",
        pairs.len(),
        worst[0],
        worst[1],
        worst[2]
    );
}

#[test]
fn psnr_and_ssim_match_recorded_reference_values() {
    let name = "psnr_and_ssim_match_recorded_reference_values";
    let Some(shared) = common::shared_dir() else {
        return common::skip(name, "../shared/metrics-ref not found");
    };
    for (a, b, want) in reference_pairs(&shared) {
        let got = rust_metrics(&a, &b);
        for (i, key) in ["psnr", "ssim_deblurnerf", "ssim_gaussian11"]
            .iter()
            .enumerate()
        {
            let w = want[key].as_f64().unwrap();
            assert!(
                (got[i] - w).abs() < TOL,
                "{key} {}: {} vs reference {w}",
                a.display(),
                got[i]
            );
        }
    }
}

#[test]
fn psnr_matches_the_baseline_recorded_by_the_dataset() {
    let name = "psnr_matches_the_baseline_recorded_by_the_dataset";
    let Some(shared) = common::shared_dir() else {
        return common::skip(name, "../shared/bench not found");
    };
    let scene = shared.join("bench/defocus-dev/dev-table");
    let lens: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(scene.join("lens.json")).unwrap()).unwrap();
    for (file, want) in lens["baseline"]["psnr_per_view"].as_object().unwrap() {
        let got = rust_metrics(
            &scene.join("images").join(file),
            &scene.join("baseline").join(file),
        );
        // lens.json rounds to 4 decimals.
        assert!(
            (got[0] - want.as_f64().unwrap()).abs() < 6e-5,
            "{file}: {}",
            got[0]
        );
    }
}
