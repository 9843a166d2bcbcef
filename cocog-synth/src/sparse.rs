//! A COLMAP model standing in for structure from motion: exact poses, and a noisy subsample
//! of the Gaussian centres as points, each observed by the train views that really see it.

use cocog_engine::Camera;
use cocog_engine::reference::Image64;
use cocog_formats::colmap::{
    Camera as ColmapCamera, CameraModel, Image, Model, Point2D, Point3D, TrackElement,
};
use cocog_formats::pose::colmap_from_world;

use crate::rig::{Split, ViewSpec};
use crate::rng::Rng;
use crate::scene::Scene;

/// Positional noise of the points (scene units) and of their 2D observations (pixels): about
/// what COLMAP reaches on sharp small images, so initialisation is realistic but not exact.
pub const POINT_NOISE: f64 = 0.004;
pub const KEYPOINT_NOISE_PX: f64 = 0.3;

/// Pixel coordinates and depth of `p` seen by `cam`, when it is in front of it.
pub fn project(cam: &Camera, p: [f64; 3]) -> Option<([f64; 2], f64)> {
    let (r, t) = cam.camera_from_world();
    let q: [f64; 3] =
        std::array::from_fn(|i| r[i][0] * p[0] + r[i][1] * p[1] + r[i][2] * p[2] + t[i]);
    (q[2] > 1e-6).then(|| {
        (
            [cam.fx * q[0] / q[2] + cam.cx, cam.fy * q[1] / q[2] + cam.cy],
            q[2],
        )
    })
}

/// Depth of the surface at pixel `xy` of a pinhole render, if the pixel is mostly covered.
fn surface_depth(img: &Image64, xy: [f64; 2]) -> Option<f64> {
    let (x, y) = (xy[0].floor(), xy[1].floor());
    if x < 0.0 || y < 0.0 || x >= f64::from(img.width) || y >= f64::from(img.height) {
        return None;
    }
    let i = y as usize * img.width as usize + x as usize;
    (img.alpha[i] > 0.5).then(|| img.depth[i] / img.alpha[i])
}

/// Nearest and farthest covered depth of a pinhole render: the LLFF bounds of that view.
pub fn depth_bounds(img: &Image64) -> Option<(f64, f64)> {
    img.alpha
        .iter()
        .zip(&img.depth)
        .filter(|(a, _)| **a > 0.5)
        .map(|(a, d)| d / a)
        .fold(None, |acc, d| match acc {
            None => Some((d, d)),
            Some((lo, hi)) => Some((lo.min(d), hi.max(d))),
        })
}

/// Builds the model from the views and their pinhole renders (same order). At most `max_points`
/// Gaussians are tried; a point is kept when at least two train views see it unoccluded.
pub fn build_model(
    scene: &Scene,
    views: &[ViewSpec],
    pinhole: &[Image64],
    max_points: usize,
    seed: u64,
) -> Model {
    let mut rng = Rng::fork(seed, 4);
    let mut images: Vec<Image> = views
        .iter()
        .map(|v| {
            let (qvec, tvec) = colmap_from_world(&v.camera.world_from_camera);
            Image {
                id: v.index as u32 + 1,
                qvec,
                tvec,
                camera_id: 1,
                name: v.name.clone(),
                points2d: Vec::new(),
            }
        })
        .collect();
    let mut order: Vec<usize> = (0..scene.gaussians.len()).collect();
    rng.shuffle(&mut order);
    let mut points = Vec::new();
    for &g in order.iter().take(max_points) {
        let centre = scene.gaussians.means[g];
        let seen: Vec<(usize, [f64; 2])> = views
            .iter()
            .zip(pinhole)
            .filter(|(v, _)| v.split == Split::Train)
            .filter_map(|(v, img)| {
                let (xy, z) = project(&v.camera, centre)?;
                // Unoccluded: the surface at that pixel is the point's own (within a few %).
                let d = surface_depth(img, xy)?;
                ((d - z).abs() < 0.03 * z + 0.01).then_some((v.index, xy))
            })
            .collect();
        if seen.len() < 2 {
            continue;
        }
        let id = points.len() as u64 + 1;
        let xyz = centre.map(|c| c + POINT_NOISE * rng.normal());
        let mut track = Vec::with_capacity(seen.len());
        let mut err = 0.0;
        for (vi, xy) in &seen {
            let obs = xy.map(|c| c + KEYPOINT_NOISE_PX * rng.normal());
            if let Some((reproj, _)) = project(&views[*vi].camera, xyz) {
                err += (reproj[0] - obs[0]).hypot(reproj[1] - obs[1]);
            }
            let img = &mut images[*vi];
            track.push(TrackElement {
                image_id: img.id,
                point2d_idx: img.points2d.len() as u32,
            });
            img.points2d.push(Point2D {
                xy: obs,
                point3d_id: Some(id),
            });
        }
        points.push(Point3D {
            id,
            xyz,
            rgb: scene.colors[g].map(|c| (c * 255.0).round() as u8),
            error: err / seen.len() as f64,
            track,
        });
    }
    let cam = &views[0].camera;
    Model {
        cameras: vec![ColmapCamera {
            id: 1,
            model: CameraModel::Pinhole,
            width: u64::from(cam.width),
            height: u64::from(cam.height),
            params: vec![cam.fx, cam.fy, cam.cx, cam.cy],
        }],
        images,
        points,
    }
}
