//! cocog's `.spz` read back by Niantic's own library (`@adobe/spz`, its C++ built to
//! WebAssembly, run by Node from `tests/browser`), asking for the PLY's RDF axes: every value
//! must come back within its quantisation step, so the layout, the quantisers, the
//! smallest-three rotations, the SH order and the RUB turn are all checked against the format's
//! reference reader. Then `cocog export --format spz` end to end.
//!
//! Needs Node.js and `npm ci --prefix tests/browser` (`.ci/run` does both); without CI=true a
//! missing one skips with the reason.

use std::path::Path;
use std::process::Command;

use cocog_formats::rng::SplitMix64;
use cocog_formats::splats::{Splats, sigmoid};
use cocog_formats::spz::write_spz;
use cocog_tests::{
    browser_dir, cocog, node_package_missing, path_str, scene_with_gaussians, skip_because, stderr,
};
use serde_json::Value;

fn niantic_read(file: &Path) -> Value {
    let o = Command::new("node")
        .current_dir(browser_dir())
        .arg("spz_decode.mjs")
        .arg(file)
        .output()
        .expect("run node");
    assert!(
        o.status.success(),
        "spz_decode.mjs {}: {}",
        file.display(),
        String::from_utf8_lossy(&o.stderr)
    );
    serde_json::from_slice(&o.stdout).expect("decoder JSON")
}

fn floats(v: &Value, key: &str) -> Vec<f64> {
    v[key]
        .as_array()
        .unwrap_or_else(|| panic!("{key}"))
        .iter()
        .map(|x| x.as_f64().expect("number"))
        .collect()
}

/// Random splats spanning each quantiser's range, SH degree `degree`.
fn splats(n: usize, degree: u32) -> Splats {
    let mut rng = SplitMix64::new(11);
    let mut u = |lo: f64, hi: f64| (lo + (hi - lo) * rng.next_f64()) as f32;
    let mut s = Splats::with_capacity(n, degree);
    let k = s.rest_per_channel();
    for _ in 0..n {
        s.means
            .extend([u(-1500.0, 1500.0), u(-3.0, 3.0), u(-0.01, 0.01)]);
        s.log_scales
            .extend([u(-9.5, 5.5), u(-6.0, 0.0), u(-3.0, 1.0)]);
        // Unnormalised, any sign: the writer normalises.
        s.rotations
            .extend([u(-2.0, 2.0), u(-2.0, 2.0), u(-2.0, 2.0), u(-2.0, 2.0)]);
        s.opacities.push(u(-6.0, 6.0));
        s.sh_dc.extend([u(-3.2, 3.2), u(-3.2, 3.2), u(-3.2, 3.2)]);
        for _ in 0..3 * k {
            s.sh_rest.push(u(-0.95, 0.95));
        }
    }
    s
}

fn check_close(what: &str, i: usize, got: f64, want: f64, step: f64) {
    assert!(
        (got - want).abs() <= step,
        "{what} of splat {i}: Niantic read {got}, wrote {want} (step {step})"
    );
}

#[test]
fn niantic_reads_back_what_cocog_wrote() {
    if skip_because(node_package_missing("@adobe/spz")) {
        return;
    }
    let dir = tempfile::tempdir().expect("tempdir");
    for degree in [0, 1, 3] {
        let s = splats(300, degree);
        let file = dir.path().join(format!("d{degree}.spz"));
        write_spz(&file, &s).expect("write spz");
        let r = niantic_read(&file);
        assert_eq!(r["numPoints"], 300);
        assert_eq!(r["shDegree"], degree);
        assert_eq!(r["antialiased"], false);
        let (pos, scales, rots) = (
            floats(&r, "positions"),
            floats(&r, "scales"),
            floats(&r, "rotations"),
        );
        let (alphas, colors, sh) = (floats(&r, "alphas"), floats(&r, "colors"), floats(&r, "sh"));
        let k = s.rest_per_channel();
        assert_eq!(sh.len(), 300 * 3 * k);
        for i in 0..300 {
            for a in 0..3 {
                let j = 3 * i + a;
                // Half a fixed-point step (2^-13), plus half an f32 ulp at 1500 (6e-5).
                check_close("position", i, pos[j], f64::from(s.means[j]), 1.9e-4);
                check_close(
                    "log scale",
                    i,
                    scales[j],
                    f64::from(s.log_scales[j]),
                    1.0 / 32.0 + 1e-6,
                );
                check_close(
                    "colour",
                    i,
                    colors[j],
                    f64::from(s.sh_dc[j]),
                    0.5 / 38.25 + 1e-6,
                );
            }
            let alpha = sigmoid(alphas[i] as f32);
            check_close(
                "alpha",
                i,
                f64::from(alpha),
                f64::from(sigmoid(s.opacities[i])),
                0.5 / 255.0 + 1e-6,
            );
            // Niantic's rotations are xyzw; the same rotation up to the quaternion's sign.
            let q = &s.rotations[4 * i..4 * i + 4];
            let norm = q.iter().map(|v| f64::from(*v).powi(2)).sum::<f64>().sqrt();
            let want = [q[1], q[2], q[3], q[0]].map(|v| f64::from(v) / norm);
            // Per component, signs matched: the three packed ones within half a 9-bit step of
            // 1/√2, the largest (rebuilt from the unit norm) within three.
            let got = &rots[4 * i..4 * i + 4];
            let largest = (0..4)
                .max_by(|&a, &b| want[a].abs().total_cmp(&want[b].abs()))
                .expect("four");
            let sign = if want[largest] * got[largest] < 0.0 {
                -1.0
            } else {
                1.0
            };
            let half_step = 0.5 * std::f64::consts::FRAC_1_SQRT_2 / 511.0 + 1e-6;
            for c in 0..4 {
                let step = if c == largest {
                    3.0 * half_step
                } else {
                    half_step
                };
                check_close("rotation", i, sign * got[c], want[c], step);
            }
            for j in 0..k {
                // Degree 1 keeps 5 bits (a bucket of 8/128), higher degrees 4 (16/128): half a
                // bucket plus the rounding to 1/128 before it.
                let step = if j < 3 { 4.5 / 128.0 } else { 8.5 / 128.0 } + 1e-6;
                for c in 0..3 {
                    let want = f64::from(s.sh_rest[i * 3 * k + c * k + j]);
                    check_close("SH", i, sh[(i * k + j) * 3 + c], want, step);
                }
            }
        }
    }
}

#[test]
fn export_writes_spz_that_niantic_reads() {
    if skip_because(node_package_missing("@adobe/spz")) {
        return;
    }
    let dir = tempfile::tempdir().expect("tempdir");
    let scene = dir.path().join("scene");
    scene_with_gaussians(&scene);
    let out = dir.path().join("scene.spz");
    let o = cocog(&[
        "export",
        path_str(&scene),
        "--format",
        "spz",
        "-o",
        path_str(&out),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let r = niantic_read(&out);
    assert_eq!(r["numPoints"], 1);
    let pos = floats(&r, "positions");
    assert!(pos.iter().all(|p| p.abs() < 1e-3), "{pos:?}");
    let scales = floats(&r, "scales");
    assert!(
        scales.iter().all(|s| (s + 2.0).abs() < 1.0 / 32.0),
        "{scales:?}"
    );
}
