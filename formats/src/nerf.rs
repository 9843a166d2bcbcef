//! NeRF-style `transforms.json`: Blender `transforms_{train,test}.json` and the nerfstudio /
//! instant-ngp superset. Poses are camera-to-world with OpenGL camera axes; we hand out OpenCV.

use std::path::{Path, PathBuf};

use serde_json::{Map, Value, json};

use crate::atomic::write_atomic;
use crate::colmap::{Pinhole, check_focal, show};
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
        let fx = focal(
            self.fl_x,
            self.camera_angle_x,
            width,
            ["fl_x", "camera_angle_x"],
        )?;
        let fy = focal(
            self.fl_y,
            self.camera_angle_y,
            height,
            ["fl_y", "camera_angle_y"],
        )?;
        let (fx, fy) = match (fx, fy) {
            (Some(x), Some(y)) => (x, y),
            (Some(f), None) | (None, Some(f)) => (f, f),
            (None, None) => {
                return Err("no focal length: expected fl_x/fl_y or camera_angle_x".to_owned());
            }
        };
        let cx = self.cx.unwrap_or(width / 2.0);
        let cy = self.cy.unwrap_or(height / 2.0);
        for (key, v) in [("cx", cx), ("cy", cy)] {
            if !v.is_finite() {
                return Err(format!(
                    "{key}: expected a finite number of pixels, got {v}"
                ));
            }
        }
        Ok(Pinhole { fx, fy, cx, cy })
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

/// The focal length along one axis of `size` pixels, from `keys[0]` (pixels) or else
/// `keys[1]` (field of view in radians).
fn focal(
    fl: Option<f64>,
    angle: Option<f64>,
    size: f64,
    keys: [&str; 2],
) -> Result<Option<f64>, String> {
    let (key, f) = match (fl, angle) {
        (Some(f), _) => (keys[0].to_owned(), f),
        (None, Some(a)) => (
            format!(
                "{} (from {} = {} rad)",
                keys[0].replace("fl_", "f"),
                keys[1],
                show(a)
            ),
            0.5 * size / (0.5 * a).tan(),
        ),
        (None, None) => return Ok(None),
    };
    check_focal(&key, f, size)?;
    Ok(Some(f))
}

#[derive(Debug, Clone, PartialEq)]
pub struct NerfFrame {
    /// As written in the file, relative to the JSON's directory.
    pub file_path: String,
    /// The transforms file the frame was read from, and its index in that file's `frames`.
    pub source: PathBuf,
    pub index: usize,
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

    /// The file name a scene gives the frame's view (what ingest names it): the last part of
    /// `file_path`, with `.png` appended when Blender left the extension off.
    pub fn image_name(&self) -> String {
        let name = Path::new(&self.file_path)
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        if Path::new(&name).extension().is_none() {
            format!("{name}.png")
        } else {
            name
        }
    }
}

/// Where a value sits, for messages: the file, `frames[i].` (empty at the top level), and the
/// frame's `file_path`, which is what a person searches the file for.
struct Place<'a> {
    path: &'a Path,
    ctx: String,
    image: Option<&'a str>,
}

impl Place<'_> {
    fn err(&self, key: &str, message: impl Into<String>) -> FormatError {
        let mut message = message.into();
        if let Some(image) = self.image {
            message = format!("{message} (frame with file_path {image:?})");
        }
        let field = format!("{}{key}", self.ctx);
        FormatError::invalid(self.path, field.trim_end_matches('.'), message)
    }
}

fn num(obj: &Map<String, Value>, key: &str, at: &Place) -> Result<Option<f64>> {
    match obj.get(key) {
        None | Some(Value::Null) => Ok(None),
        Some(v) => v
            .as_f64()
            .map(Some)
            .ok_or_else(|| at.err(key, format!("expected a number, got {v}"))),
    }
}

/// A number that must lie in `ok`, described by `expected` when it does not.
fn num_in(
    obj: &Map<String, Value>,
    key: &str,
    at: &Place,
    ok: impl Fn(f64) -> bool,
    expected: &str,
) -> Result<Option<f64>> {
    match num(obj, key, at)? {
        Some(v) if !(v.is_finite() && ok(v)) => {
            Err(at.err(key, format!("expected {expected}, got {}", show(v))))
        }
        v => Ok(v),
    }
}

fn camera(obj: &Map<String, Value>, at: &Place) -> Result<NerfCamera> {
    for key in ["k1", "k2", "k3", "k4", "p1", "p2"] {
        if let Some(k) = num(obj, key, at)?.filter(|k| *k != 0.0) {
            return Err(FormatError::unsupported(
                at.path,
                format!(
                    "{}{key} = {k}: distorted cameras are not supported; undistort the images first",
                    at.ctx
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
            at.path,
            format!(
                "{}camera_model {model:?}: only perspective (PINHOLE/OPENCV without distortion) cameras are supported",
                at.ctx
            ),
        ));
    }
    let focal = |k| num_in(obj, k, at, |v| v > 0.0, "a focal length above 0 pixels");
    let centre = |k| num_in(obj, k, at, |_| true, "a finite number of pixels");
    let size = |k| {
        num_in(
            obj,
            k,
            at,
            |v| v.round() >= 1.0 && v.round() <= f64::from(u32::MAX),
            "an image size of at least 1 pixel",
        )
    };
    let angle = |k| {
        num_in(
            obj,
            k,
            at,
            |v| v > 0.0 && v < std::f64::consts::PI,
            "a field of view in radians, above 0 and below π",
        )
    };
    Ok(NerfCamera {
        fl_x: focal("fl_x")?,
        fl_y: focal("fl_y")?,
        cx: centre("cx")?,
        cy: centre("cy")?,
        w: size("w")?,
        h: size("h")?,
        camera_angle_x: angle("camera_angle_x")?,
        camera_angle_y: angle("camera_angle_y")?,
    })
}

fn matrix(v: Option<&Value>, at: &Place) -> Result<Mat4> {
    const KEY: &str = "transform_matrix";
    let expected = "expected a 4×4 (or 3×4) array of rows of numbers";
    let rows = v.and_then(Value::as_array).ok_or_else(|| {
        at.err(
            KEY,
            format!("{expected}, got {}", v.unwrap_or(&Value::Null)),
        )
    })?;
    if !(rows.len() == 4 || rows.len() == 3) {
        let n = rows.len();
        return Err(at.err(
            KEY,
            format!("{expected}, got {n} row{}", if n == 1 { "" } else { "s" }),
        ));
    }
    let mut m = [
        [0.0, 0.0, 0.0, 0.0],
        [0.0; 4],
        [0.0; 4],
        [0.0, 0.0, 0.0, 1.0],
    ];
    for (i, row) in rows.iter().enumerate() {
        let row = row.as_array().filter(|r| r.len() == 4).ok_or_else(|| {
            let got = row
                .as_array()
                .map_or(format!("{row}"), |r| format!("{} entries", r.len()));
            at.err(KEY, format!("{expected}, but row {i} has {got}"))
        })?;
        for (j, x) in row.iter().enumerate() {
            // serde_json maps NaN to null and refuses numbers beyond f64.
            m[i][j] = x.as_f64().ok_or_else(|| {
                at.err(
                    KEY,
                    format!("entry [{i}][{j}] is {x}, expected a finite number"),
                )
            })?;
        }
    }
    if m[3] != [0.0, 0.0, 0.0, 1.0] {
        let row: Vec<String> = m[3].iter().map(|v| show(*v)).collect();
        return Err(at.err(
            KEY,
            format!("row 3 is [{}], expected [0, 0, 0, 1]", row.join(", ")),
        ));
    }
    check_rigid(&m, 1e-4).map_err(|e| at.err(KEY, e))?;
    Ok(m)
}

/// Whether serde_json stopped (1-based `line`, `column`: the character it could not read) at
/// Python's spelling of a non-finite float.
fn non_finite_at(text: &str, line: usize, column: usize) -> bool {
    let Some(l) = text.lines().nth(line.saturating_sub(1)) else {
        return false;
    };
    let at = l.get(column.saturating_sub(1)..).unwrap_or("");
    ["NaN", "Infinity", "-Infinity"]
        .iter()
        .any(|w| at.starts_with(w))
}

/// Reads one transforms file; `split` labels frames that carry no `split` key of their own.
pub fn read_transforms(path: &Path, split: Option<&str>) -> Result<Vec<NerfFrame>> {
    let text = read_text(path)?;
    let root: Value = serde_json::from_str(&text).map_err(|e| {
        let hint = if e.to_string().contains("out of range") {
            " (a number beyond the range of a 64-bit float)"
        } else if non_finite_at(&text, e.line(), e.column()) {
            " (NaN or Infinity, which JSON has no numbers for: Python's json.dump writes them \
             unless given allow_nan=False; a pose or intrinsic there is not a number)"
        } else {
            ""
        };
        FormatError::invalid(path, "json", format!("{e}{hint}"))
    })?;
    let top = root.as_object().ok_or_else(|| {
        FormatError::invalid(path, "json", "expected a JSON object at the top level")
    })?;
    let top_camera = camera(
        top,
        &Place {
            path,
            ctx: String::new(),
            image: None,
        },
    )?;
    let frames = top
        .get("frames")
        .and_then(Value::as_array)
        .ok_or_else(|| FormatError::invalid(path, "frames", "expected an array of frames"))?;
    frames
        .iter()
        .enumerate()
        .map(|(i, f)| {
            let mut at = Place {
                path,
                ctx: format!("frames[{i}]."),
                image: None,
            };
            let obj = f.as_object().ok_or_else(|| {
                FormatError::invalid(path, format!("frames[{i}]"), "expected an object")
            })?;
            let file_path = obj
                .get("file_path")
                .and_then(Value::as_str)
                .ok_or_else(|| at.err("file_path", "expected a string"))?;
            at.image = Some(file_path);
            let gl = matrix(obj.get("transform_matrix"), &at)?;
            let cam = top_camera.merge(&camera(obj, &at)?);
            // With the size in the file the focal can be checked here, naming the file; Blender
            // files give none, and their readers check against the image's own size.
            if let (Some(w), Some(h)) = (cam.w, cam.h) {
                cam.pinhole(w.round(), h.round())
                    .map_err(|e| at.err("", e))?;
            }
            let text_of = |k: &str| obj.get(k).and_then(Value::as_str).map(str::to_owned);
            Ok(NerfFrame {
                file_path: file_path.to_owned(),
                source: path.to_path_buf(),
                index: i,
                world_from_camera: flip_yz_camera_axes(&gl),
                camera: cam,
                split: text_of("split").or_else(|| split.map(str::to_owned)),
                depth_file_path: text_of("depth_file_path"),
                focus_distance: num(obj, "focus_distance_m", &at)?,
                aperture_radius: num(obj, "aperture_radius_m", &at)?,
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

/// The point cloud a dataset's `transforms.json` names (`ply_file_path`, nerfstudio's seed
/// points, in the poses' world frame), resolved against its folder; `None` when it names none
/// or the dataset is Blender's split files.
pub fn ply_file_path(dir: &Path) -> Result<Option<std::path::PathBuf>> {
    let path = dir.join("transforms.json");
    if !path.is_file() {
        return Ok(None);
    }
    let root: Value = serde_json::from_str(&read_text(&path)?)
        .map_err(|e| FormatError::invalid(&path, "json", e.to_string()))?;
    match root.get("ply_file_path") {
        None | Some(Value::Null) => Ok(None),
        Some(Value::String(p)) => Ok(Some(dir.join(p))),
        Some(other) => Err(FormatError::invalid(
            &path,
            "ply_file_path",
            format!("expected a relative path to a PLY point cloud, got {other}"),
        )),
    }
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
pub fn write_transforms(
    path: &Path,
    frames: &[NerfFrameOut],
    ply_file_path: Option<&str>,
) -> Result<()> {
    let mut top = Map::new();
    top.insert("camera_model".into(), json!("PINHOLE"));
    // nerfstudio's initial point cloud (splatfacto seeds from it), relative to the file.
    if let Some(p) = ply_file_path {
        top.insert("ply_file_path".into(), json!(p));
    }
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
