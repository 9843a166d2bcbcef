//! Single-channel EXR: round trip, OpenEXR-python both ways, the bench depth maps.

mod common;

use cocog_formats::exr_map::{FloatMap, read_exr, write_exr};

fn ramp(width: usize, height: usize) -> FloatMap {
    FloatMap {
        width,
        height,
        data: (0..width * height)
            .map(|i| 0.5 + (i as f32 * 0.37).sin() * 0.25 + (i / width) as f32)
            .collect(),
    }
}

#[test]
fn exr_round_trips() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("d.exr");
    let map = ramp(37, 23);
    write_exr(&p, &map).unwrap();
    assert_eq!(read_exr(&p).unwrap(), map);
    let e = write_exr(
        &p,
        &FloatMap {
            width: 3,
            height: 3,
            data: vec![0.0; 8],
        },
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("d.exr") && e.contains("3×3"), "{e}");
    std::fs::write(&p, b"not an exr").unwrap();
    let e = read_exr(&p).unwrap_err().to_string();
    assert!(e.contains("d.exr") && e.contains("OpenEXR"), "{e}");
}

#[test]
fn openexr_python_agrees_both_ways() {
    if !common::python_has(&["OpenEXR", "numpy"]) {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let ours = dir.path().join("ours.exr");
    let map = ramp(31, 17);
    write_exr(&ours, &map).unwrap();
    let script = r#"
import sys, numpy as np, OpenEXR
ch = OpenEXR.File(sys.argv[1]).channels()
assert list(ch) == ['Y'], list(ch)
y = ch['Y'].pixels
assert y.dtype == np.float32 and y.shape == (17, 31), (y.dtype, y.shape)
y.astype('<f4').tofile(sys.argv[2])
hdr = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
z = (np.arange(12 * 5, dtype=np.float32).reshape(5, 12) * 0.5 + 1.0)
OpenEXR.File(hdr, {"Z": z}).write(sys.argv[3])
rgb = {"R": z * 2, "G": z, "B": z}
OpenEXR.File(hdr, rgb).write(sys.argv[4])
OpenEXR.File(hdr, {"A": z, "G": z}).write(sys.argv[5])
"#;
    let raw = dir.path().join("y.f32");
    let [z, rgb, ag] = ["z.exr", "rgb.exr", "ag.exr"].map(|n| dir.path().join(n));
    common::run_python(
        script,
        &[
            ours.to_str().unwrap(),
            raw.to_str().unwrap(),
            z.to_str().unwrap(),
            rgb.to_str().unwrap(),
            ag.to_str().unwrap(),
        ],
    );
    let back: Vec<f32> = std::fs::read(&raw)
        .unwrap()
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
        .collect();
    assert_eq!(back, map.data);
    let expect: Vec<f32> = (0..60).map(|i| i as f32 * 0.5 + 1.0).collect();
    let zm = read_exr(&z).unwrap();
    assert_eq!((zm.width, zm.height), (12, 5));
    assert_eq!(zm.data, expect);
    assert_eq!(
        read_exr(&rgb).unwrap().data,
        expect.iter().map(|v| v * 2.0).collect::<Vec<_>>()
    );
    let e = read_exr(&ag).unwrap_err().to_string();
    assert!(e.contains("ag.exr") && e.contains("channels"), "{e}");
}

#[test]
fn bench_depth_maps_are_read_in_metres() {
    for scene in common::dev_scenes() {
        let lens: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(scene.join("lens.json")).unwrap())
                .unwrap();
        for (i, view) in lens["views"]
            .as_array()
            .unwrap()
            .iter()
            .enumerate()
            .step_by(7)
        {
            let d = read_exr(&scene.join(format!("depth/{i:03}.exr"))).unwrap();
            assert_eq!((d.width, d.height), (400, 300));
            let min = d.data.iter().copied().fold(f32::INFINITY, f32::min);
            let max = d.data.iter().copied().fold(f32::NEG_INFINITY, f32::max);
            let (lo, hi) = (
                view["depth_min_m"].as_f64().unwrap() as f32,
                view["depth_max_m"].as_f64().unwrap() as f32,
            );
            // lens.json rounds to 0.1 mm.
            assert!(
                (min - lo).abs() < 1e-3 && (max - hi).abs() < 1e-3,
                "view {i}: {min}..{max} vs {lo}..{hi}"
            );
        }
    }
}
