//! COLMAP text model files (`doc/format.rst`): `#` comments, whitespace-separated fields.

use std::fmt::Write as _;
use std::io::Write as _;
use std::path::Path;
use std::str::FromStr;

use super::check::Ids;
use super::{Camera, CameraModel, Image, Model, Point2D, Point3D, TrackElement};
use crate::atomic::{io_at, write_atomic};
use crate::error::{FormatError, Result, read_text};

/// Tokens of one line with enough context to name a bad field.
struct Line<'a> {
    path: &'a Path,
    number: usize,
    tokens: Vec<&'a str>,
}

impl<'a> Line<'a> {
    fn get<T: FromStr>(&self, index: usize, field: &str) -> Result<T> {
        let tok = self.tokens.get(index).ok_or_else(|| {
            FormatError::invalid(
                self.path,
                format!("line {}: {field}", self.number),
                "missing value (line too short)",
            )
        })?;
        tok.parse().map_err(|_| {
            FormatError::invalid(
                self.path,
                format!("line {}: {field}", self.number),
                format!("cannot parse {tok:?} as {}", std::any::type_name::<T>()),
            )
        })
    }

    fn err(&self, field: &str, message: impl Into<String>) -> FormatError {
        FormatError::invalid(self.path, format!("line {}: {field}", self.number), message)
    }

    /// The error for an id an earlier line already has.
    fn duplicate(
        &self,
        field: &str,
        kind: &str,
        id: impl std::fmt::Display,
        first: usize,
    ) -> FormatError {
        self.err(
            field,
            format!("duplicate {kind} id {id}: line {first} has it too; ids must be unique"),
        )
    }
}

/// Non-comment lines with 1-based numbers; blank lines are kept because `images.txt` uses them.
/// A leading UTF-8 byte order mark (Windows editors add one) is not part of the first line.
fn data_lines<'a>(path: &'a Path, text: &'a str) -> impl Iterator<Item = Line<'a>> {
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    text.lines()
        .enumerate()
        .filter(|(_, l)| !l.trim_start().starts_with('#'))
        .map(move |(i, l)| Line {
            path,
            number: i + 1,
            tokens: l.split_whitespace().collect(),
        })
}

/// Reads `cameras.txt`, `images.txt` and `points3D.txt` from `dir`.
pub fn read_txt(dir: &Path) -> Result<Model> {
    let model = Model {
        cameras: parse_cameras(
            &dir.join("cameras.txt"),
            &read_text(&dir.join("cameras.txt"))?,
        )?,
        images: parse_images(
            &dir.join("images.txt"),
            &read_text(&dir.join("images.txt"))?,
        )?,
        points: parse_points(
            &dir.join("points3D.txt"),
            &read_text(&dir.join("points3D.txt"))?,
        )?,
    };
    super::validate(&model, &dir.join("images.txt"))?;
    Ok(model)
}

pub(crate) fn parse_cameras(path: &Path, text: &str) -> Result<Vec<Camera>> {
    let mut out = Vec::new();
    let mut ids = Ids::with_capacity(0);
    for line in data_lines(path, text).filter(|l| !l.tokens.is_empty()) {
        let name = line.tokens.get(1).copied().unwrap_or("");
        let model = CameraModel::from_name(name).ok_or_else(|| {
            line.err(
                "MODEL",
                format!(
                    "unknown camera model {name:?}, expected a COLMAP model name such as PINHOLE"
                ),
            )
        })?;
        let want = 4 + model.num_params();
        if line.tokens.len() != want {
            let hint = if line.tokens.len() < want {
                "is WIDTH, HEIGHT or a parameter missing?"
            } else {
                "too many fields"
            };
            return Err(line.err(
                "PARAMS",
                format!(
                    "{name} needs {} parameters after CAMERA_ID MODEL WIDTH HEIGHT, {want} fields in all; the line has {} ({hint})",
                    model.num_params(),
                    line.tokens.len(),
                ),
            ));
        }
        let params = (0..model.num_params())
            .map(|k| line.get(4 + k, &format!("PARAMS[{k}]")))
            .collect::<Result<_>>()?;
        let id = line.get(0, "CAMERA_ID")?;
        if let Some(first) = ids.repeat(id, line.number) {
            return Err(line.duplicate("CAMERA_ID", "camera", id, first));
        }
        let cam = Camera {
            id,
            model,
            width: line.get(2, "WIDTH")?,
            height: line.get(3, "HEIGHT")?,
            params,
        };
        super::check::camera(&cam, |field, msg| {
            line.err(&format!("camera {}.{field}", cam.id), msg)
        })?;
        out.push(cam);
    }
    Ok(out)
}

pub(crate) fn parse_images(path: &Path, text: &str) -> Result<Vec<Image>> {
    let mut out = Vec::new();
    let mut ids = Ids::with_capacity(0);
    let mut lines = data_lines(path, text);
    while let Some(head) = lines.next() {
        if head.tokens.is_empty() {
            continue;
        }
        if head.tokens.len() != 10 {
            return Err(head.err(
                "IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME",
                format!(
                    "expected 10 fields, got {} (names with spaces cannot be stored in .txt)",
                    head.tokens.len()
                ),
            ));
        }
        let mut qvec = [0.0; 4];
        for (k, q) in qvec.iter_mut().enumerate() {
            *q = head.get(1 + k, ["QW", "QX", "QY", "QZ"][k])?;
        }
        let mut tvec = [0.0; 3];
        for (k, t) in tvec.iter_mut().enumerate() {
            *t = head.get(5 + k, ["TX", "TY", "TZ"][k])?;
        }
        // The points line may be empty (an image without keypoints) or absent at the end of the file.
        let mut points2d = Vec::new();
        if let Some(pts) = lines.next() {
            if pts.tokens.len() % 3 != 0 {
                return Err(pts.err(
                    "POINTS2D",
                    format!(
                        "expected triples X Y POINT3D_ID, got {} values",
                        pts.tokens.len()
                    ),
                ));
            }
            for k in 0..pts.tokens.len() / 3 {
                let id: i128 = pts.get(3 * k + 2, &format!("POINTS2D[{k}].POINT3D_ID"))?;
                if id < -1 || id >= i128::from(u64::MAX) {
                    return Err(pts.err(
                        &format!("POINTS2D[{k}].POINT3D_ID"),
                        format!("{id} is out of range, expected −1 or a u64 id"),
                    ));
                }
                points2d.push(Point2D {
                    xy: [
                        pts.get(3 * k, &format!("POINTS2D[{k}].X"))?,
                        pts.get(3 * k + 1, &format!("POINTS2D[{k}].Y"))?,
                    ],
                    point3d_id: (id >= 0).then_some(id as u64),
                });
            }
        }
        let id = head.get(0, "IMAGE_ID")?;
        if let Some(first) = ids.repeat(id, head.number) {
            return Err(head.duplicate("IMAGE_ID", "image", id, first));
        }
        let img = Image {
            id,
            qvec,
            tvec,
            camera_id: head.get(8, "CAMERA_ID")?,
            name: head.tokens[9].to_owned(),
            points2d,
        };
        super::check::image(&img, |field, msg| {
            head.err(&format!("image {} ({}).{field}", img.id, img.name), msg)
        })?;
        out.push(img);
    }
    Ok(out)
}

pub(crate) fn parse_points(path: &Path, text: &str) -> Result<Vec<Point3D>> {
    let mut out = Vec::new();
    let mut ids = Ids::with_capacity(0);
    for line in data_lines(path, text).filter(|l| !l.tokens.is_empty()) {
        if line.tokens.len() < 8 || (line.tokens.len() - 8) % 2 != 0 {
            return Err(line.err(
                "POINT3D_ID X Y Z R G B ERROR TRACK[]",
                format!(
                    "expected 8 fields plus (IMAGE_ID, POINT2D_IDX) pairs, got {} fields",
                    line.tokens.len()
                ),
            ));
        }
        let track = (0..(line.tokens.len() - 8) / 2)
            .map(|k| {
                Ok(TrackElement {
                    image_id: line.get(8 + 2 * k, &format!("TRACK[{k}].IMAGE_ID"))?,
                    point2d_idx: line.get(9 + 2 * k, &format!("TRACK[{k}].POINT2D_IDX"))?,
                })
            })
            .collect::<Result<_>>()?;
        let id = line.get(0, "POINT3D_ID")?;
        if let Some(first) = ids.repeat(id, line.number) {
            return Err(line.duplicate("POINT3D_ID", "point3D", id, first));
        }
        let point = Point3D {
            id,
            xyz: [line.get(1, "X")?, line.get(2, "Y")?, line.get(3, "Z")?],
            rgb: [line.get(4, "R")?, line.get(5, "G")?, line.get(6, "B")?],
            error: line.get(7, "ERROR")?,
            track,
        };
        super::check::point(&point, |field, msg| {
            line.err(&format!("point3D {}.{field}", point.id), msg)
        })?;
        out.push(point);
    }
    Ok(out)
}

/// Writes the model as `cameras.txt`, `images.txt`, `points3D.txt` into the existing `dir`.
/// Floats use Rust's shortest round-trip formatting, so reading back is exact.
pub fn write_txt(model: &Model, dir: &Path) -> Result<()> {
    for img in &model.images {
        if img.name.is_empty() || img.name.chars().any(char::is_whitespace) {
            return Err(FormatError::invalid(
                dir.join("images.txt"),
                format!("image {}.name", img.id),
                format!(
                    "{:?} is empty or contains whitespace, which COLMAP text files cannot store; use .bin",
                    img.name
                ),
            ));
        }
    }
    let path = dir.join("cameras.txt");
    write_atomic(&path, |w| {
        let mut s = format!(
            "# Camera list with one line of data per camera:\n#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n# Number of cameras: {}\n",
            model.cameras.len()
        );
        for c in &model.cameras {
            let _ = write!(s, "{} {} {} {}", c.id, c.model.name(), c.width, c.height);
            for p in &c.params {
                let _ = write!(s, " {p}");
            }
            s.push('\n');
        }
        w.write_all(s.as_bytes()).map_err(io_at(&path))
    })?;
    let path = dir.join("images.txt");
    write_atomic(&path, |w| {
        let header = format!(
            "# Image list with two lines of data per image:\n#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n#   POINTS2D[] as (X, Y, POINT3D_ID)\n# Number of images: {}\n",
            model.images.len()
        );
        w.write_all(header.as_bytes()).map_err(io_at(&path))?;
        let mut s = String::new();
        for img in &model.images {
            s.clear();
            let [qw, qx, qy, qz] = img.qvec;
            let [tx, ty, tz] = img.tvec;
            let _ = writeln!(
                s,
                "{} {qw} {qx} {qy} {qz} {tx} {ty} {tz} {} {}",
                img.id, img.camera_id, img.name
            );
            let pts: Vec<String> = img
                .points2d
                .iter()
                .map(|p| {
                    format!(
                        "{} {} {}",
                        p.xy[0],
                        p.xy[1],
                        p.point3d_id.map_or(-1, |v| v as i128)
                    )
                })
                .collect();
            s.push_str(&pts.join(" "));
            s.push('\n');
            w.write_all(s.as_bytes()).map_err(io_at(&path))?;
        }
        Ok(())
    })?;
    let path = dir.join("points3D.txt");
    write_atomic(&path, |w| {
        let header = format!(
            "# 3D point list with one line of data per point:\n#   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)\n# Number of points: {}\n",
            model.points.len()
        );
        w.write_all(header.as_bytes()).map_err(io_at(&path))?;
        let mut s = String::new();
        for p in &model.points {
            s.clear();
            let [x, y, z] = p.xyz;
            let [r, g, b] = p.rgb;
            let _ = write!(s, "{} {x} {y} {z} {r} {g} {b} {}", p.id, p.error);
            for t in &p.track {
                let _ = write!(s, " {} {}", t.image_id, t.point2d_idx);
            }
            s.push('\n');
            w.write_all(s.as_bytes()).map_err(io_at(&path))?;
        }
        Ok(())
    })
}
