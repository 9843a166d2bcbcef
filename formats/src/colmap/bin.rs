//! COLMAP binary model files (`reconstruction_io_binary.cc` layouts, little-endian, unaligned).

use std::io::Write;
use std::path::Path;

use super::check::Ids;
use super::{Camera, CameraModel, Image, Model, Point2D, Point3D, TrackElement};
use crate::atomic::{io_at, write_atomic};
use crate::bytes::ByteReader;
use crate::error::{FormatError, Result, read_file};

/// Reads `cameras.bin`, `images.bin` and `points3D.bin` from `dir`.
pub fn read_bin(dir: &Path) -> Result<Model> {
    let model = Model {
        cameras: read_cameras(&dir.join("cameras.bin"))?,
        images: read_images(&dir.join("images.bin"))?,
        points: read_points(&dir.join("points3D.bin"))?,
    };
    super::validate(&model, &dir.join("images.bin"))?;
    Ok(model)
}

pub(crate) fn read_cameras(path: &Path) -> Result<Vec<Camera>> {
    let data = read_file(path)?;
    parse_cameras(path, &data)
}

pub(crate) fn parse_cameras(path: &Path, data: &[u8]) -> Result<Vec<Camera>> {
    let mut r = ByteReader::new(path, data);
    let n = r.count("num_cameras", 24)?;
    let mut out = Vec::with_capacity(n);
    let mut ids = Ids::with_capacity(n);
    for i in 0..n {
        let f = |name: &'static str| move || format!("camera[{i}].{name}");
        let id = r.u32(&f("camera_id"))?;
        if let Some(first) = ids.repeat(id, i) {
            return Err(duplicate(path, f("camera_id")(), "camera", id, first));
        }
        let model_id = r.i32(&f("model_id"))?;
        let model = CameraModel::from_id(model_id).ok_or_else(|| {
            FormatError::invalid(
                path,
                f("model_id")(),
                format!("unknown camera model id {model_id}, expected 0..=17"),
            )
        })?;
        let width = r.u64(&f("width"))?;
        let height = r.u64(&f("height"))?;
        let params = (0..model.num_params())
            .map(|k| {
                r.f64(&|| {
                    format!(
                        "camera[{i}].params[{k}] ({} has {})",
                        model.name(),
                        model.num_params()
                    )
                })
            })
            .collect::<Result<Vec<_>>>()?;
        let cam = Camera {
            id,
            model,
            width,
            height,
            params,
        };
        super::check::camera(&cam, |field, msg| {
            FormatError::invalid(path, format!("camera {id}.{field}"), msg)
        })?;
        out.push(cam);
    }
    r.finish("num_cameras")?;
    Ok(out)
}

/// A record whose id an earlier record (`kind[first]`) already has.
fn duplicate(
    path: &Path,
    field: String,
    kind: &str,
    id: impl std::fmt::Display,
    first: usize,
) -> FormatError {
    FormatError::invalid(
        path,
        field,
        format!("duplicate {kind} id {id}: {kind}[{first}] has it too; ids must be unique"),
    )
}

pub(crate) fn read_images(path: &Path) -> Result<Vec<Image>> {
    let data = read_file(path)?;
    parse_images(path, &data)
}

pub(crate) fn parse_images(path: &Path, data: &[u8]) -> Result<Vec<Image>> {
    let mut r = ByteReader::new(path, data);
    let n = r.count("num_reg_images", 4 + 56 + 4 + 1 + 8)?;
    let mut out = Vec::with_capacity(n);
    let mut ids = Ids::with_capacity(n);
    for i in 0..n {
        let f = |name: &'static str| move || format!("image[{i}].{name}");
        let id = r.u32(&f("image_id"))?;
        if let Some(first) = ids.repeat(id, i) {
            return Err(duplicate(path, f("image_id")(), "image", id, first));
        }
        let mut qvec = [0.0; 4];
        for q in &mut qvec {
            *q = r.f64(&f("qvec"))?;
        }
        let mut tvec = [0.0; 3];
        for t in &mut tvec {
            *t = r.f64(&f("tvec"))?;
        }
        let camera_id = r.u32(&f("camera_id"))?;
        let name = r.cstr(&f("name"))?;
        let np = r.count(&format!("image[{i}] ({name}).num_points2D"), 24)?;
        let mut points2d = Vec::with_capacity(np);
        for _ in 0..np {
            let x = r.f64(&f("points2D.x"))?;
            let y = r.f64(&f("points2D.y"))?;
            let pid = r.u64(&f("points2D.point3D_id"))?;
            points2d.push(Point2D {
                xy: [x, y],
                point3d_id: (pid != u64::MAX).then_some(pid),
            });
        }
        let img = Image {
            id,
            qvec,
            tvec,
            camera_id,
            name,
            points2d,
        };
        super::check::image(&img, |field, msg| {
            FormatError::invalid(path, format!("image {id} ({}).{field}", img.name), msg)
        })?;
        out.push(img);
    }
    r.finish("num_reg_images")?;
    Ok(out)
}

pub(crate) fn read_points(path: &Path) -> Result<Vec<Point3D>> {
    let data = read_file(path)?;
    parse_points(path, &data)
}

pub(crate) fn parse_points(path: &Path, data: &[u8]) -> Result<Vec<Point3D>> {
    let mut r = ByteReader::new(path, data);
    let n = r.count("num_points", 8 + 24 + 3 + 8 + 8)?;
    let mut out = Vec::with_capacity(n);
    let mut ids = Ids::with_capacity(n);
    for i in 0..n {
        let f = |name: &'static str| move || format!("point3D[{i}].{name}");
        let id = r.u64(&f("point3D_id"))?;
        if let Some(first) = ids.repeat(id, i) {
            return Err(duplicate(path, f("point3D_id")(), "point3D", id, first));
        }
        let mut xyz = [0.0; 3];
        for v in &mut xyz {
            *v = r.f64(&f("xyz"))?;
        }
        let rgb = [r.u8(&f("rgb"))?, r.u8(&f("rgb"))?, r.u8(&f("rgb"))?];
        let error = r.f64(&f("error"))?;
        let nt = r.count(&format!("point3D[{i}].track_length"), 8)?;
        let mut track = Vec::with_capacity(nt);
        for _ in 0..nt {
            let image_id = r.u32(&f("track.image_id"))?;
            let point2d_idx = r.u32(&f("track.point2D_idx"))?;
            track.push(TrackElement {
                image_id,
                point2d_idx,
            });
        }
        let point = Point3D {
            id,
            xyz,
            rgb,
            error,
            track,
        };
        super::check::point(&point, |field, msg| {
            FormatError::invalid(path, format!("point3D {id}.{field}"), msg)
        })?;
        out.push(point);
    }
    r.finish("num_points")?;
    Ok(out)
}

/// Writes the model as `cameras.bin`, `images.bin`, `points3D.bin` into the existing `dir`.
pub fn write_bin(model: &Model, dir: &Path) -> Result<()> {
    for cam in &model.cameras {
        if cam.params.len() != cam.model.num_params() {
            return Err(FormatError::invalid(
                dir.join("cameras.bin"),
                format!("camera {}.params", cam.id),
                format!(
                    "{} needs {} parameters, got {}",
                    cam.model.name(),
                    cam.model.num_params(),
                    cam.params.len()
                ),
            ));
        }
    }
    for img in &model.images {
        if img.name.as_bytes().contains(&0) {
            return Err(FormatError::invalid(
                dir.join("images.bin"),
                format!("image {}.name", img.id),
                "name contains a NUL byte",
            ));
        }
    }
    let path = dir.join("cameras.bin");
    write_atomic(&path, |w| {
        let mut put = |b: &[u8]| w.write_all(b).map_err(io_at(&path));
        put(&(model.cameras.len() as u64).to_le_bytes())?;
        for c in &model.cameras {
            put(&c.id.to_le_bytes())?;
            put(&c.model.id().to_le_bytes())?;
            put(&c.width.to_le_bytes())?;
            put(&c.height.to_le_bytes())?;
            for p in &c.params {
                put(&p.to_le_bytes())?;
            }
        }
        Ok(())
    })?;
    let path = dir.join("images.bin");
    write_atomic(&path, |w| {
        let mut put = |b: &[u8]| w.write_all(b).map_err(io_at(&path));
        put(&(model.images.len() as u64).to_le_bytes())?;
        for img in &model.images {
            put(&img.id.to_le_bytes())?;
            for v in img.qvec.iter().chain(&img.tvec) {
                put(&v.to_le_bytes())?;
            }
            put(&img.camera_id.to_le_bytes())?;
            put(img.name.as_bytes())?;
            put(&[0])?;
            put(&(img.points2d.len() as u64).to_le_bytes())?;
            for p in &img.points2d {
                put(&p.xy[0].to_le_bytes())?;
                put(&p.xy[1].to_le_bytes())?;
                put(&p.point3d_id.unwrap_or(u64::MAX).to_le_bytes())?;
            }
        }
        Ok(())
    })?;
    let path = dir.join("points3D.bin");
    write_atomic(&path, |w| {
        let mut put = |b: &[u8]| w.write_all(b).map_err(io_at(&path));
        put(&(model.points.len() as u64).to_le_bytes())?;
        for p in &model.points {
            put(&p.id.to_le_bytes())?;
            for v in &p.xyz {
                put(&v.to_le_bytes())?;
            }
            put(&p.rgb)?;
            put(&p.error.to_le_bytes())?;
            put(&(p.track.len() as u64).to_le_bytes())?;
            for t in &p.track {
                put(&t.image_id.to_le_bytes())?;
                put(&t.point2d_idx.to_le_bytes())?;
            }
        }
        Ok(())
    })
}
