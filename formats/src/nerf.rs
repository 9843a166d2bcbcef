//! NeRF-style `transforms.json`: Blender `transforms_{train,test}.json` and the nerfstudio /
//! instant-ngp superset. Poses are camera-to-world with OpenGL camera axes; we hand out OpenCV.

use std::path::{Path, PathBuf};

use serde_json::{Map, Value, json};

use crate::atomic::write_atomic;
use crate::colmap::Pinhole;
use crate::error::{FormatError, Result, read_text};
use crate::pose::{Mat4, check_rigid, flip_yz_camera_axes};

/// Intrinsics as the file gives them; frame-level keys override top-level ones.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct NerfCamera {
    pub fl_x: Option<f64>,
    pub fl_y: Option<f64>,
    pub cx: Option<f64>,
    pub cy: Option<f64>,
    pub w: Option<f64>,
    pub h: Option<f64>,
    pub camera_angle_x: Option<f64>,
    pub camera_angle_y: Option<f64>,
}

impl NerfCamera {
    /// Pinhole intrinsics for an image of `width`×`height` pixels (the size the file describes,
    /// or the image's own when the file has none). Blender files give only `camera_angle_x`:
    /// `fx = fy = W / (2 tan(angle_x / 2))`, principal point at the centre.
    pub fn pinhole(&self, width: f64, height: f64) -> Result<Pinhole, String> {
        let from_angle = |a: Option<f64>, size: f64| a.map(|a| 0.5 * size / (0.5 * a).tan());
        let fx = self.fl_x.or_else(|| from_angle(self.camera_angle_x, width));
        let fy = self
            .fl_y
            .or_else(|| from_angle(self.camera_angle_y, height));
        let (fx, fy) = match (fx, fy) {
            (Some(x), Some(y)) => (x, y),
            (Some(f), None) | (None, Some(f)) => (f, f),
            (None, None) => {
                return Err("no focal length: expected fl_x/fl_y or camera_angle_x".to_owned());
            }
        };
        let p = Pinhole {
            fx,
            fy,
            cx: self.cx.unwrap_or(width / 2.0),
            cy: self.cy.unwrap_or(height / 2.0),
        };
        if [p.fx, p.fy, p.cx, p.cy].iter().any(|v| !v.is_finite()) || p.fx <= 0.0 || p.fy <= 0.0 {
            return Err(format!(
                "focal lengths must be finite and positive, got {p:?}"
            ));
        }
        Ok(p)
    }

    fn merge(&self, over: &NerfCamera) -> NerfCamera {
        NerfCamera {
            fl_x: over.fl_x.or(self.fl_x),
            fl_y: over.fl_y.or(self.fl_y),
            cx: over.cx.or(self.cx),
            cy: over.cy.or(self.cy),
            w: over.w.or(self.w),
            h: over.h.or(self.h),
            camera_angle_x: over.camera_angle_x.or(self.camera_angle_x),
            camera_angle_y: over.camera_angle_y.or(self.camera_angle_y),
        }
    }
}

#[derive(Debug, Clone, PartialEq)]
pub struct NerfFrame {
    /// As written in the file, relative to the JSON's directory.
    pub file_path: String,
    /// `world_from_camera` in OpenCV camera axes (converted from the file's OpenGL axes).
    pub world_from_camera: Mat4,
    pub camera: NerfCamera,
    /// `"train"`/`"test"`/`"val"`: the frame's `split` key, or the Blender file it came from.
    pub split: Option<String>,
    pub depth_file_path: Option<String>,
    /// Per-frame lens metadata of the cocog bench (`focus_distance_m`, `aperture_radius_m`).
    pub focus_distance: Option<f64>,
    pub aperture_radius: Option<f64>,
}

impl NerfFrame {
    /// The image file: `file_path` against `base`, with `.png` appended when Blender left it off.
    pub fn image_path(&self, base: &Path) -> PathBuf {
        let p = base.join(&self.file_path);
        if p.extension().is_none() && !p.is_file() {
            p.with_extension("png")
        } else {
            p
        }
    }
}

fn num(obj: &Map<String, Value>, key: &str, path: &Path, ctx: &str) -> Result<Option<f64>> {
    match obj.get(key) {
        None | Some(Value::Null) => Ok(None),
        Some(v) => v.as_f64().map(Some).ok_or_else(|| {
            FormatError::invalid(
                path,
                format!("{ctx}{key}"),
                format!("expected a number, got {v}"),
            )
        }),
    }
}

fn camera(obj: &Map<String, Value>, path: &Path, ctx: &str) -> Result<NerfCamera> {
    for key in ["k1", "k2", "k3", "k4", "p1", "p2"] {
        if let Some(k) = num(obj, key, path, ctx)?.filter(|k| *k != 0.0) {
            return Err(FormatError::unsupported(
                path,
                format!(
                    "{ctx}{key} = {k}: distorted cameras are not supported; undistort the images first"
                ),
            ));
        }
    }
    if let Some(model) = obj
        .get("camera_model")
        .and_then(Value::as_str)
        .filter(|m| !matches!(*m, "PINHOLE" | "OPENCV" | "SIMPLE_PINHOLE"))
    {
        return Err(FormatError::unsupported(
            path,
            format!(
                "{ctx}camera_model {model:?}: only perspective (PINHOLE/OPENCV without distortion) cameras are supported"
            ),
        ));
    }
    Ok(NerfCamera {
        fl_x: num(obj, "fl_x", path, ctx)?,
        fl_y: num(obj, "fl_y", path, ctx)?,
        cx: num(obj, "cx", path, ctx)?,
        cy: num(obj, "cy", path, ctx)?,
        w: num(obj, "w", path, ctx)?,
        h: num(obj, "h", path, ctx)?,
        camera_angle_x: num(obj, "camera_angle_x", path, ctx)?,
        camera_angle_y: num(obj, "camera_angle_y", path, ctx)?,
    })
}

fn matrix(v: Option<&Value>, path: &Path, field: &str) -> Result<Mat4> {
    let bad = || {
        FormatError::invalid(
            path,
            field,
            "expected a 4×4 (or 3×4) array of numbers (rows)",
        )
    };
    let rows = v.and_then(Value::as_array).ok_or_else(bad)?;
    if !(rows.len() == 4 || rows.len() == 3) {
        return Err(bad());
    }
    let mut m = [
        [0.0, 0.0, 0.0, 0.0],
        [0.0; 4],
        [0.0; 4],
        [0.0, 0.0, 0.0, 1.0],
    ];
    for (i, row) in rows.iter().enumerate() {
        let row = row.as_array().filter(|r| r.len() == 4).ok_or_else(bad)?;
        for (j, x) in row.iter().enumerate() {
            // serde_json maps NaN to null; either way it is not a pose.
            m[i][j] = x.as_f64().ok_or_else(|| {
                FormatError::invalid(
                    path,
                    field,
                    format!("entry [{i}][{j}] is {x}, expected a finite number"),
                )
            })?;
        }
    }
    check_rigid(&m, 1e-4).map_err(|e| FormatError::invalid(path, field, e))?;
    Ok(m)
}

/// Reads one transforms file; `split` labels frames that carry no `split` key of their own.
pub fn read_transforms(path: &Path, split: Option<&str>) -> Result<Vec<NerfFrame>> {
    let text = read_text(path)?;
    let root: Value = serde_json::from_str(&text)
        .map_err(|e| FormatError::invalid(path, "json", e.to_string()))?;
    let top = root.as_object().ok_or_else(|| {
        FormatError::invalid(path, "json", "expected a JSON object at the top level")
    })?;
    let top_camera = camera(top, path, "")?;
    let frames = top
        .get("frames")
        .and_then(Value::as_array)
        .ok_or_else(|| FormatError::invalid(path, "frames", "expected an array of frames"))?;
    frames
        .iter()
        .enumerate()
        .map(|(i, f)| {
            let ctx = format!("frames[{i}].");
            let obj = f.as_object().ok_or_else(|| {
                FormatError::invalid(path, format!("frames[{i}]"), "expected an object")
            })?;
            let file_path = obj
                .get("file_path")
                .and_then(Value::as_str)
                .ok_or_else(|| {
                    FormatError::invalid(path, format!("{ctx}file_path"), "expected a string")
                })?;
            let gl = matrix(
                obj.get("transform_matrix"),
                path,
                &format!("{ctx}transform_matrix"),
            )?;
            let text_of = |k: &str| obj.get(k).and_then(Value::as_str).map(str::to_owned);
            Ok(NerfFrame {
                file_path: file_path.to_owned(),
                world_from_camera: flip_yz_camera_axes(&gl),
                camera: top_camera.merge(&camera(obj, path, &ctx)?),
                split: text_of("split").or_else(|| split.map(str::to_owned)),
                depth_file_path: text_of("depth_file_path"),
                focus_distance: num(obj, "focus_distance_m", path, &ctx)?,
                aperture_radius: num(obj, "aperture_radius_m", path, &ctx)?,
            })
        })
        .collect()
}

/// Reads a NeRF dataset directory: `transforms.json` if present, else Blender's
/// `transforms_train.json` and `transforms_test.json` (`val` is not used for training or scoring).
pub fn read_dataset(dir: &Path) -> Result<Vec<NerfFrame>> {
    let single = dir.join("transforms.json");
    if single.is_file() {
        return read_transforms(&single, None);
    }
    let mut frames = Vec::new();
    for split in ["train", "test"] {
        let p = dir.join(format!("transforms_{split}.json"));
        if p.is_file() {
            frames.extend(read_transforms(&p, Some(split))?);
        }
    }
    if frames.is_empty() {
        return Err(FormatError::invalid(
            dir,
            "transforms",
            "no transforms.json or transforms_{train,test}.json with frames here",
        ));
    }
    Ok(frames)
}

/// One frame to write: pose in OpenCV axes, pinhole intrinsics and image size.
#[derive(Debug, Clone, PartialEq)]
pub struct NerfFrameOut {
    pub file_path: String,
    pub world_from_camera: Mat4,
    pub intrinsics: Pinhole,
    pub width: u32,
    pub height: u32,
    pub split: Option<String>,
}

/// Writes a nerfstudio-style `transforms.json` with per-frame intrinsics (and top-level ones when
/// every frame shares them, for tools that read only those).
pub fn write_transforms(path: &Path, frames: &[NerfFrameOut]) -> Result<()> {
    let mut top = Map::new();
    top.insert("camera_model".into(), json!("PINHOLE"));
    let intr = |f: &NerfFrameOut| json!({"fl_x": f.intrinsics.fx, "fl_y": f.intrinsics.fy, "cx": f.intrinsics.cx, "cy": f.intrinsics.cy, "w": f.width, "h": f.height});
    if let Some(first) = frames.first().filter(|f0| {
        frames
            .iter()
            .all(|f| f.intrinsics == f0.intrinsics && (f.width, f.height) == (f0.width, f0.height))
    }) {
        top.extend(intr(first).as_object().cloned().unwrap_or_default());
    }
    let out: Vec<Value> = frames
        .iter()
        .map(|f| {
            let mut o = intr(f).as_object().cloned().unwrap_or_default();
            o.insert("file_path".into(), json!(f.file_path));
            o.insert(
                "transform_matrix".into(),
                json!(flip_yz_camera_axes(&f.world_from_camera)),
            );
            if let Some(s) = &f.split {
                o.insert("split".into(), json!(s));
            }
            Value::Object(o)
        })
        .collect();
    top.insert("frames".into(), Value::Array(out));
    let text = serde_json::to_string_pretty(&Value::Object(top))
        .map_err(|e| FormatError::invalid(path, "json", e.to_string()))?;
    write_atomic(path, |w| {
        std::io::Write::write_all(w, text.as_bytes()).map_err(|e| FormatError::io(path, e))
    })
}
