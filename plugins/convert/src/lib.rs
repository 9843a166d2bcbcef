//! The `convert` stage: writes a scene as a dataset another tool can read, with its images
//! copied beside it.
//!
//! - `to = "colmap"`: `sparse/0/{cameras,images,points3D}.txt` (PINHOLE cameras, the scene's
//!   point cloud as points without tracks) + `images/`.
//! - `to = "nerf"`: nerfstudio-style `transforms.json` (OpenGL camera-to-world, per-frame
//!   intrinsics and split, `ply_file_path` naming the scene's points copied as `points.ply`)
//!   + `images/`.

use std::path::Path;

use cocog_formats::colmap::{self, CameraModel, Pinhole};
use cocog_formats::nerf::{NerfFrameOut, write_transforms};
use cocog_formats::pose::colmap_from_world;
use cocog_pipeline::{
    Context, OptionSpec, OutputKind, Scene, Split, Stage, StageError, StageInfo, StageKind,
    StageRequest,
};
use serde_json::{Value, json};

pub struct Convert;

fn input_error(e: cocog_formats::FormatError) -> StageError {
    StageError::Input(e.to_string())
}

/// Copies every view's image to `out/images/<view name>`.
fn copy_images(
    scene: &Scene,
    input: &Path,
    out: &Path,
    ctx: &dyn Context,
) -> Result<(), StageError> {
    for (i, v) in scene.views.iter().enumerate() {
        ctx.check_cancelled()?;
        ctx.progress("copy images", i as u64, scene.views.len() as u64);
        if Path::new(&v.name)
            .components()
            .any(|c| !matches!(c, std::path::Component::Normal(_)))
        {
            return Err(StageError::Input(format!(
                "{}: view name {:?} is not a plain relative path",
                input.join("scene.json").display(),
                v.name
            )));
        }
        let src = Scene::resolve(input, &v.image);
        let dst = out.join("images").join(&v.name);
        if let Some(parent) = dst.parent() {
            std::fs::create_dir_all(parent).map_err(|e| StageError::io(parent, e))?;
        }
        std::fs::copy(&src, &dst).map_err(|e| StageError::io(&src, e))?;
    }
    Ok(())
}

fn to_colmap(scene: &Scene, input: &Path, out: &Path) -> Result<(), StageError> {
    let cameras = scene
        .cameras
        .iter()
        .map(|c| colmap::Camera {
            id: c.id,
            model: CameraModel::Pinhole,
            width: u64::from(c.width),
            height: u64::from(c.height),
            params: vec![c.fx, c.fy, c.cx, c.cy],
        })
        .collect();
    let images = scene
        .views
        .iter()
        .enumerate()
        .map(|(i, v)| {
            let (qvec, tvec) = colmap_from_world(&v.world_from_camera);
            colmap::Image {
                id: i as u32 + 1,
                qvec,
                tvec,
                camera_id: v.camera,
                name: v.name.clone(),
                points2d: Vec::new(),
            }
        })
        .collect();
    let points = match &scene.points {
        Some(p) => {
            let cloud =
                cocog_formats::ply::read_points(&Scene::resolve(input, p)).map_err(input_error)?;
            cloud
                .positions
                .chunks_exact(3)
                .zip(cloud.colors.chunks_exact(3))
                .enumerate()
                .map(|(i, (p, c))| colmap::Point3D {
                    id: i as u64 + 1,
                    xyz: [p[0], p[1], p[2]].map(f64::from),
                    rgb: [c[0], c[1], c[2]],
                    error: -1.0,
                    track: Vec::new(),
                })
                .collect()
        }
        None => Vec::new(),
    };
    let dir = out.join("sparse/0");
    std::fs::create_dir_all(&dir).map_err(|e| StageError::io(&dir, e))?;
    colmap::write_txt(
        &colmap::Model {
            cameras,
            images,
            points,
        },
        &dir,
    )
    .map_err(input_error)
}

fn to_nerf(scene: &Scene, input: &Path, out: &Path) -> Result<(), StageError> {
    let frames: Vec<NerfFrameOut> = scene
        .views
        .iter()
        .map(|v| {
            let c = scene
                .camera(v.camera)
                .expect("validated scene: every view's camera exists");
            NerfFrameOut {
                file_path: format!("images/{}", v.name),
                world_from_camera: v.world_from_camera,
                intrinsics: Pinhole {
                    fx: c.fx,
                    fy: c.fy,
                    cx: c.cx,
                    cy: c.cy,
                },
                width: c.width,
                height: c.height,
                split: Some(
                    match v.split {
                        Split::Train => "train",
                        Split::Test => "test",
                    }
                    .to_owned(),
                ),
            }
        })
        .collect();
    // The points go along as a PLY the transforms name, in the same world frame.
    let ply = match &scene.points {
        Some(stored) => {
            let src = Scene::resolve(input, stored);
            let dst = out.join("points.ply");
            std::fs::copy(&src, &dst).map_err(|e| StageError::io(&src, e))?;
            Some("points.ply")
        }
        None => None,
    };
    write_transforms(&out.join("transforms.json"), &frames, ply).map_err(input_error)
}

impl Stage for Convert {
    fn info(&self) -> StageInfo {
        StageInfo {
            name: "convert".to_owned(),
            kind: StageKind::Convert,
            output: OutputKind::Dir,
            needs_gaussians: false,
            description:
                "Write the scene as a COLMAP text model or a transforms.json dataset, images copied"
                    .to_owned(),
            options: vec![OptionSpec::string("to", "colmap", "colmap | nerf")],
        }
    }

    fn run(&self, req: &StageRequest, ctx: &dyn Context) -> Result<Value, StageError> {
        let to = req.options.get_str("to").unwrap_or("colmap");
        if !matches!(to, "colmap" | "nerf") {
            return Err(StageError::Options(format!(
                "convert: option 'to' must be colmap or nerf, got {to:?}"
            )));
        }
        let scene = Scene::load(&req.input)?;
        if to == "colmap" {
            to_colmap(&scene, &req.input, &req.output)?;
        } else {
            to_nerf(&scene, &req.input, &req.output)?;
        }
        copy_images(&scene, &req.input, &req.output, ctx)?;
        ctx.info(&format!(
            "convert: wrote {} views as {to}",
            scene.views.len()
        ));
        Ok(json!({"to": to, "views": scene.views.len(), "cameras": scene.cameras.len()}))
    }
}

/// The convert stage, for the CLI to register.
pub fn stages() -> Vec<Box<dyn Stage>> {
    vec![Box::new(Convert)]
}
