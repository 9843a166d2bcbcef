//! poses_bounds.npy values out of range and malformed `hold=N` markers are refused, naming the
//! file, the row and the field.

use std::path::Path;

use cocog_formats::llff;
use npyz::WriterBuilder;

/// One valid row: identity pose (LLFF columns [down, right, back]), 300×400 image, focal 350,
/// near 1, far 10.
fn row() -> [f64; 17] {
    [
        0.0, 1.0, 0.0, 0.5, 300.0, //
        1.0, 0.0, 0.0, 0.0, 400.0, //
        0.0, 0.0, -1.0, 2.0, 350.0, //
        1.0, 10.0,
    ]
}

fn write_npy(path: &Path, rows: &[[f64; 17]]) {
    let mut f = std::fs::File::create(path).unwrap();
    let mut w = npyz::WriteOptions::<f64>::new()
        .default_dtype()
        .shape(&[rows.len() as u64, 17])
        .writer(&mut f)
        .begin_nd()
        .unwrap();
    w.extend(rows.iter().flatten().copied()).unwrap();
    w.finish().unwrap();
}

/// The error of reading three rows, the middle one with `column` set to `value`.
fn err_with(column: usize, value: f64) -> String {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("poses_bounds.npy");
    let mut bad = row();
    bad[column] = value;
    write_npy(&p, &[row(), bad, row()]);
    let err = llff::read_poses_bounds(&p).unwrap_err().to_string();
    assert!(err.contains("poses_bounds.npy"), "{err}");
    assert!(err.contains("row 1: "), "{err}");
    err
}

#[test]
fn the_valid_row_reads() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("poses_bounds.npy");
    write_npy(&p, &[row()]);
    let v = llff::read_poses_bounds(&p).unwrap();
    assert_eq!(v[0].hwf, [300.0, 400.0, 350.0]);
}

#[test]
fn non_finite_values_name_the_field() {
    let e = err_with(3, f64::NAN);
    assert!(e.contains("row 1: pose[0][3]") && e.contains("NaN"), "{e}");
    let e = err_with(9, f64::INFINITY);
    assert!(e.contains("row 1: width") && e.contains("inf"), "{e}");
    let e = err_with(16, f64::INFINITY);
    assert!(e.contains("row 1: far") && e.contains("inf"), "{e}");
}

#[test]
fn bounds_must_be_positive_and_ordered() {
    for near in [0.0, -1.0] {
        let e = err_with(15, near);
        assert!(e.contains("row 1: near") && e.contains("above 0"), "{e}");
    }
    for far in [1.0, 0.5] {
        let e = err_with(16, far);
        assert!(
            e.contains("row 1: far") && e.contains("above near (1)"),
            "{e}"
        );
    }
}

#[test]
fn sizes_and_focal_must_be_positive() {
    let e = err_with(14, 0.0);
    assert!(e.contains("row 1: focal") && e.contains("got 0"), "{e}");
    let e = err_with(14, -350.0);
    assert!(e.contains("row 1: focal") && e.contains("got -350"), "{e}");
    let e = err_with(4, 0.0);
    assert!(e.contains("row 1: height") && e.contains("got 0"), "{e}");
}

#[test]
fn hold_markers_must_be_one_non_negative_integer() {
    for name in ["hold=-1", "hold=x", "hold=", "hold=99999999999"] {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join(name), b"").unwrap();
        let err = llff::read_hold_marker(dir.path()).unwrap_err().to_string();
        assert!(
            err.contains(name) && err.contains("non-negative integer"),
            "{name}: {err}"
        );
    }
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("hold=0"), b"").unwrap();
    assert_eq!(llff::read_hold_marker(dir.path()).unwrap(), Some(0));
    std::fs::write(dir.path().join("hold=8"), b"").unwrap();
    let err = llff::read_hold_marker(dir.path()).unwrap_err().to_string();
    assert!(
        err.contains("hold=0") && err.contains("hold=8") && err.contains("one"),
        "{err}"
    );
}

#[test]
fn absurd_focal_lengths_are_refused() {
    let e = err_with(14, 1e308);
    assert!(e.contains("row 1: focal") && e.contains("at most"), "{e}");
}
