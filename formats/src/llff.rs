//! LLFF `poses_bounds.npy` (N×17: a row-major 3×5 `[R | C | hwf]` camera-to-world with R's
//! columns [down, right, back], then near and far) and the `hold=N` split marker.

use std::io::Write;
use std::path::Path;

use npyz::{DType, NpyFile, Order, TypeChar, WriterBuilder};

use crate::atomic::{io_at, write_atomic};
use crate::colmap::check_focal;
use crate::error::{FormatError, Result, read_file};
use crate::pose::{Mat4, check_rigid};

/// One LLFF row, with the pose already converted to OpenCV camera axes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LlffView {
    /// `world_from_camera`, OpenCV camera axes (x right, y down, z forward), row-major.
    pub world_from_camera: Mat4,
    /// Height, width and focal length in pixels of the full-resolution images.
    pub hwf: [f64; 3],
    pub near: f64,
    pub far: f64,
}

/// Tolerance for "is a rotation": loose enough for poses saved as float32.
const ROTATION_TOL: f64 = 1e-4;

/// Reads `poses_bounds.npy`: float32 or float64, either byte order, C or Fortran layout.
pub fn read_poses_bounds(path: &Path) -> Result<Vec<LlffView>> {
    let bytes = read_file(path)?;
    crate::npy_header::vet(&bytes).map_err(|why| {
        FormatError::invalid(path, "header", format!("not a valid .npy file: {why}"))
    })?;
    let npy = NpyFile::new(&bytes[..])
        .map_err(|e| FormatError::invalid(path, "header", format!("not a .npy file: {e}")))?;
    let shape = npy.shape().to_vec();
    let [n, 17] = shape[..] else {
        return Err(FormatError::invalid(
            path,
            "shape",
            format!("expected (N, 17), got {shape:?}"),
        ));
    };
    let n = n as usize;
    let order = npy.order();
    let size = match npy.dtype() {
        DType::Plain(ts)
            if ts.type_char() == TypeChar::Float && matches!(ts.size_field(), 4 | 8) =>
        {
            ts.size_field()
        }
        other => {
            return Err(FormatError::invalid(
                path,
                "dtype",
                format!("expected float32 or float64, got {}", other.descr()),
            ));
        }
    };
    let bad_data = |e: std::io::Error| {
        FormatError::invalid(path, "data", format!("cannot read {n}×17 values: {e}"))
    };
    let flat: Vec<f64> = if size == 8 {
        npy.into_vec::<f64>().map_err(bad_data)?
    } else {
        npy.into_vec::<f32>()
            .map_err(bad_data)?
            .into_iter()
            .map(f64::from)
            .collect()
    };
    if flat.len() != n * 17 {
        return Err(FormatError::invalid(
            path,
            "data",
            format!("expected {} values, got {}", n * 17, flat.len()),
        ));
    }
    let at = |i: usize, j: usize| match order {
        Order::C => flat[i * 17 + j],
        Order::Fortran => flat[j * n + i],
    };
    (0..n)
        .map(|i| {
            let raw: [f64; 17] = std::array::from_fn(|j| at(i, j));
            check_row(path, i, &raw)?;
            let m = |r: usize, c: usize| raw[r * 5 + c];
            let mut w = [[0.0; 4]; 4];
            for (r, row) in w.iter_mut().take(3).enumerate() {
                *row = [m(r, 1), m(r, 0), -m(r, 2), m(r, 3)];
            }
            w[3] = [0.0, 0.0, 0.0, 1.0];
            check_rigid(&w, ROTATION_TOL)
                .map_err(|e| FormatError::invalid(path, format!("row {i}: pose"), e))?;
            Ok(LlffView {
                world_from_camera: w,
                hwf: [m(0, 4), m(1, 4), m(2, 4)],
                near: raw[15],
                far: raw[16],
            })
        })
        .collect()
}

/// What column `c` of a row holds, in the file's own terms.
fn column_name(c: usize) -> String {
    match c {
        4 => "height".into(),
        9 => "width".into(),
        14 => "focal".into(),
        15 => "near".into(),
        16 => "far".into(),
        _ => format!("pose[{}][{}]", c / 5, c % 5),
    }
}

/// Refuses values no camera can have, before they become a pose or a projection.
fn check_row(path: &Path, i: usize, raw: &[f64; 17]) -> Result<()> {
    let bad = |c: usize, expected: String| {
        FormatError::invalid(
            path,
            format!("row {i}: {}", column_name(c)),
            format!("expected {expected}, got {}", raw[c]),
        )
    };
    if let Some(c) = raw.iter().position(|v| !v.is_finite()) {
        return Err(bad(c, "a finite number".into()));
    }
    for c in [4, 9] {
        if !(1.0..=f64::from(u32::MAX)).contains(&raw[c].round()) {
            return Err(bad(c, "an image size of at least 1 pixel".into()));
        }
    }
    if raw[14] <= 0.0 {
        return Err(bad(14, "a focal length above 0 pixels".into()));
    }
    check_focal("focal", raw[14], raw[4].min(raw[9]).round())
        .map_err(|e| FormatError::invalid(path, format!("row {i}: focal"), e))?;
    if raw[15] <= 0.0 {
        return Err(bad(15, "a depth above 0".into()));
    }
    if raw[16] <= raw[15] {
        return Err(bad(16, format!("a depth above near ({})", raw[15])));
    }
    Ok(())
}

/// Writes `poses_bounds.npy` as float64, C order, converting OpenCV poses back to LLFF columns.
pub fn write_poses_bounds(path: &Path, views: &[LlffView]) -> Result<()> {
    let mut flat = Vec::with_capacity(views.len() * 17);
    for v in views {
        let w = &v.world_from_camera;
        for (r, row) in w.iter().take(3).enumerate() {
            flat.extend_from_slice(&[row[1], row[0], -row[2], row[3], v.hwf[r]]);
        }
        flat.extend_from_slice(&[v.near, v.far]);
    }
    write_atomic(path, |w| {
        let mut npy = npyz::WriteOptions::new()
            .default_dtype()
            .shape(&[views.len() as u64, 17])
            .writer(&mut *w)
            .begin_nd()
            .map_err(io_at(path))?;
        npy.extend(flat.iter().copied()).map_err(io_at(path))?;
        npy.finish().map_err(io_at(path))?;
        w.flush().map_err(io_at(path))
    })
}

/// The `hold=N` marker file of Deblur-NeRF-style scenes, if present: test views are
/// `index % N == 0`; `hold=0` (BAD-Gaussians) means every view trains. The value is in the
/// name; the file is empty.
pub fn read_hold_marker(dir: &Path) -> Result<Option<u32>> {
    let mut markers = Vec::new();
    for entry in std::fs::read_dir(dir).map_err(|e| FormatError::io(dir, e))? {
        let name = entry.map_err(|e| FormatError::io(dir, e))?.file_name();
        if let Some(name) = name.to_str().filter(|s| s.starts_with("hold=")) {
            markers.push(name.to_owned());
        }
    }
    markers.sort();
    match &markers[..] {
        [] => Ok(None),
        [name] => {
            let value = &name["hold=".len()..];
            value.parse::<u32>().map(Some).map_err(|_| {
                FormatError::invalid(
                    dir.join(name),
                    "hold",
                    format!(
                        "marker file name must be hold=<non-negative integer up to {}>, got {value:?}",
                        u32::MAX
                    ),
                )
            })
        }
        // Which one wins would depend on directory order.
        _ => Err(FormatError::invalid(
            dir,
            "hold",
            format!(
                "expected one hold=N marker file, found {}",
                markers.join(" and ")
            ),
        )),
    }
}
