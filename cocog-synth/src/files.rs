//! The dataset's metadata files. `transforms.json` is written here rather than through
//! `cocog_formats::nerf::write_transforms` because that writer has no per-frame lens keys.

use std::path::Path;

use cocog_formats::pose::flip_yz_camera_axes;
use serde_json::{Value, json};

use crate::lens::BlurSpace;
use crate::rig::{Split, ViewSpec};
use crate::{SynthConfig, SynthError, io_err};

/// Per-view facts measured while rendering, for `lens.json` and the LLFF bounds.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ViewStats {
    pub depth_min: f64,
    pub depth_max: f64,
    /// Largest circle of confusion over the covered pixels (0 for sharp views).
    pub coc_max_px: f64,
}

fn write_json(path: &Path, v: &Value) -> Result<(), SynthError> {
    let mut text = serde_json::to_string_pretty(v).map_err(|e| SynthError::Json {
        path: path.to_owned(),
        message: e.to_string(),
    })?;
    text.push('\n');
    std::fs::write(path, text).map_err(io_err(path))
}

fn lens_keys(v: &ViewSpec, stats: &ViewStats) -> Value {
    let focus = v.lens.map(|l| l.focus_distance);
    let aperture = v.lens.map_or(0.0, |l| l.aperture_radius);
    // The `_m` keys are what the bench and `cocog_formats::nerf` read; the plain ones say
    // plainly that the units are scene units.
    json!({
        "dof": v.lens.is_some(),
        "focus_distance": focus,
        "aperture_radius": aperture,
        "focus_distance_m": focus,
        "aperture_radius_m": aperture,
        "coc_max_px": stats.coc_max_px,
    })
}

/// nerfstudio-style `transforms.json`: OpenGL camera-to-world, shared pinhole intrinsics.
pub fn write_transforms(
    path: &Path,
    cfg: &SynthConfig,
    views: &[ViewSpec],
    stats: &[ViewStats],
) -> Result<(), SynthError> {
    let cam = &views[0].camera;
    let files = |test: bool| -> Vec<String> {
        views
            .iter()
            .filter(|v| (v.split == Split::Test) == test)
            .map(|v| format!("images/{}", v.name))
            .collect()
    };
    let frames: Vec<Value> = views
        .iter()
        .zip(stats)
        .map(|(v, s)| {
            let mut f = json!({
                "file_path": format!("images/{}", v.name),
                "transform_matrix": flip_yz_camera_axes(&v.camera.world_from_camera),
                "split": v.split.as_str(),
            });
            if let (Some(o), Value::Object(extra)) = (f.as_object_mut(), lens_keys(v, s)) {
                o.extend(extra);
            }
            f
        })
        .collect();
    let fov = |size: u32, f: f64| 2.0 * (0.5 * f64::from(size) / f).atan();
    write_json(
        path,
        &json!({
            "camera_model": "PINHOLE",
            "camera_angle_x": fov(cam.width, cam.fx),
            "camera_angle_y": fov(cam.height, cam.fy),
            "fl_x": cam.fx,
            "fl_y": cam.fy,
            "cx": cam.cx,
            "cy": cam.cy,
            "w": cam.width,
            "h": cam.height,
            "k1": 0.0, "k2": 0.0, "p1": 0.0, "p2": 0.0,
            "convention": "transform_matrix = camera-to-world, OpenGL camera axes (+x right, +y up, camera looks along -z); world +z up; scene units (about metres)",
            "hold": cfg.hold,
            "train_filenames": files(false),
            "test_filenames": files(true),
            "frames": frames,
        }),
    )
}

/// `lens.json`: the generator's configuration and the true lens of every view.
pub fn write_lens(
    path: &Path,
    cfg: &SynthConfig,
    views: &[ViewSpec],
    stats: &[ViewStats],
    gaussians: usize,
    points: usize,
) -> Result<(), SynthError> {
    let cam = &views[0].camera;
    let per_view: Vec<Value> = views
        .iter()
        .zip(stats)
        .map(|(v, s)| {
            let mut o = json!({
                "index": v.index,
                "file": format!("images/{}", v.name),
                "split": v.split.as_str(),
                "depth_min": s.depth_min,
                "depth_max": s.depth_max,
            });
            if let (Some(o), Value::Object(extra)) = (o.as_object_mut(), lens_keys(v, s)) {
                o.extend(extra);
            }
            o
        })
        .collect();
    let blur_space = match cfg.blur_space {
        BlurSpace::Linear => "linear (sRGB-decoded) radiance",
        BlurSpace::Display => "display (sRGB-encoded) values",
    };
    write_json(
        path,
        &json!({
            "generator": "cocog-synth",
            "generator_version": env!("CARGO_PKG_VERSION"),
            "seed": cfg.seed,
            "config": {
                "views": cfg.views,
                "width": cfg.width,
                "height": cfg.height,
                "hold": cfg.hold,
                "fov_x_deg": cfg.fov_x_deg,
                "aperture_radius": cfg.aperture_radius,
                "focus_range": cfg.focus_range,
                "lens_samples": cfg.lens_samples,
                "max_points": cfg.max_points,
                "blur_space": blur_space,
            },
            "camera": {
                "model": "PINHOLE", "fx": cam.fx, "fy": cam.fy, "cx": cam.cx, "cy": cam.cy,
                "width": cam.width, "height": cam.height,
            },
            "lens": {
                "aperture_radius": cfg.aperture_radius,
                "aperture_pattern": "Vogel spiral (golden angle), area-uniform over the disk",
                "samples": cfg.lens_samples,
                "focus_range": cfg.focus_range,
                "focus_sampling": "train views: stratified over focus_range, shuffled by seed",
                "coc_scale_px": 2.0 * cfg.aperture_radius * cam.fx,
                "coc_formula": "coc_diameter_px = coc_scale_px * |1/z - 1/s| = 2 * aperture_radius * fx * |1/z - 1/s| (pinhole + disk aperture, focal plane at camera z = s; z, s along the optical axis)",
                "blur_space": blur_space,
            },
            "scene": { "gaussians": gaussians, "units": "scene units (about metres)", "up": "+z" },
            "colmap": {
                "points": points,
                "point_noise_sigma": crate::sparse::POINT_NOISE,
                "keypoint_noise_px": crate::sparse::KEYPOINT_NOISE_PX,
                "observations": "train views only, unoccluded projections of the true centres",
            },
            "views": per_view,
        }),
    )
}

/// An 8-bit RGB PNG.
pub fn write_png(path: &Path, width: u32, height: u32, rgb: &[u8]) -> Result<(), SynthError> {
    image::save_buffer(path, rgb, width, height, image::ExtendedColorType::Rgb8).map_err(|e| {
        SynthError::Image {
            path: path.to_owned(),
            source: e,
        }
    })
}
