//! The train stage's schedule options: a preset (`auto` or `inria`) and an override for
//! every constant of it, resolved into the trainer's configuration and recorded in full.

use cocog_engine::Camera;
use cocog_pipeline::{OptionKind, OptionSpec, StageError, StageRequest};
use serde_json::{Value, json};

use crate::{DensifyConfig, PointsFrame, TrainConfig, depth_scene_scale, scene_extent};

/// Where the scene scale comes from.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ScaleRule {
    /// INRIA: 1.1 × the largest camera distance from the mean camera centre.
    CameraExtent,
    /// The larger of the camera extent and the points' median depth (`depth_scene_scale`).
    Depth,
    Fixed(f64),
}

/// Every schedule constant, after the preset and the overrides.
#[derive(Clone, Debug, PartialEq)]
pub struct Schedule {
    pub preset: &'static str,
    pub densify: DensifyConfig,
    pub sh_interval: u32,
    pub scale: ScaleRule,
    /// λ of (1 − λ)·L1 + λ·D-SSIM.
    pub lambda_dssim: f32,
    /// Position learning rate at the start and the end, × the scene scale.
    pub position_lr: [f64; 2],
    /// The units of the point addition's volume rule and cut-off distance.
    pub points_frame: PointsFrame,
}

impl Schedule {
    fn preset(name: &str) -> Result<Self, StageError> {
        let t = TrainConfig::default();
        let inria = Self {
            preset: "inria",
            densify: DensifyConfig::default(),
            sh_interval: t.sh_degree_interval,
            scale: ScaleRule::CameraExtent,
            lambda_dssim: t.lambda_dssim,
            position_lr: [t.position_lr_init, t.position_lr_final],
            points_frame: PointsFrame::Scene,
        };
        match name {
            "inria" => Ok(inria),
            "auto" => Ok(Self {
                preset: "auto",
                densify: DensifyConfig::auto(),
                ..inria
            }),
            // The released CoCoGaussian code (method.md §7–§8), which inherits Deblurring
            // 3DGS's density control.
            "deblur" => Ok(Self {
                preset: "deblur",
                densify: DensifyConfig::deblur(),
                lambda_dssim: 0.25,
                position_lr: [3.2e-4, 3.2e-6],
                ..inria
            }),
            other => Err(StageError::Options(format!(
                "stage 'train' option 'schedule': unknown preset '{other}' (use auto, deblur or \
                 inria)"
            ))),
        }
    }

    /// The preset named by option `schedule` (by default `deblur` for CoCoGaussian and
    /// `auto` for plain 3DGS, as `method` says), with every override given applied.
    pub fn from_request(req: &StageRequest, method: &str) -> Result<Self, StageError> {
        let o = &req.options;
        let default = match method {
            "3dgs" => "auto",
            _ => "deblur",
        };
        let mut s = Self::preset(o.get_str("schedule").unwrap_or(default))?;
        let d = &mut s.densify;
        let count =
            |name: &str, min: i64| -> Result<Option<u32>, StageError> {
                o.get_i64(name)
                    .map(|v| {
                        u32::try_from(v).ok().filter(|&v| i64::from(v) >= min).ok_or_else(|| {
                        StageError::Options(format!(
                            "stage 'train' option '{name}' must be an integer in {min}..={}, \
                             got {v}",
                            u32::MAX
                        ))
                    })
                    })
                    .transpose()
            };
        let fraction = |name: &str, max: f64| -> Result<Option<f32>, StageError> {
            o.get_f64(name)
                .map(|v| {
                    if v.is_finite() && (0.0..=max).contains(&v) {
                        Ok(v as f32)
                    } else {
                        Err(StageError::Options(format!(
                            "stage 'train' option '{name}' must be a number in 0..={max}, got {v}"
                        )))
                    }
                })
                .transpose()
        };
        if let Some(v) = count("densify_from", 0)? {
            d.from_iter = v;
        }
        if let Some(v) = count("densify_until", 0)? {
            d.until_iter = v;
        }
        if let Some(v) = count("densify_every", 1)? {
            d.interval = v;
        }
        if let Some(v) = count("opacity_reset_every", 0)? {
            d.opacity_reset_interval = v;
        }
        if let Some(v) = count("sh_every", 1)? {
            s.sh_interval = v;
        }
        if let Some(v) = fraction("densify_grad", 1.0)? {
            d.grad_threshold = v;
        }
        if let Some(v) = fraction("percent_dense", 1.0)? {
            d.percent_dense = v;
        }
        if let Some(v) = fraction("prune_opacity", 1.0)? {
            d.min_opacity = v;
        }
        if let Some(v) = fraction("prune_large", 1e6)? {
            d.prune_large = v;
        }
        if let Some(v) = fraction("depth_prune_range", 100.0)? {
            if v < 1.0 {
                return Err(StageError::Options(format!(
                    "stage 'train' option 'depth_prune_range' must be at least 1 (1 = uniform \
                     pruning), got {v}"
                )));
            }
            d.depth_prune_range = v;
        }
        if let Some(v) = count("add_points_at", 0)? {
            d.add_points_at = v;
        }
        if let Some(v) = count("add_points_max", 0)? {
            d.add_points_count = v;
        }
        if let Some(v) = o.get_f64("add_points_distance") {
            if !(v.is_finite() && v > 0.0) {
                return Err(StageError::Options(format!(
                    "stage 'train' option 'add_points_distance' must be a positive length in \
                     scene units, got {v}"
                )));
            }
            d.add_points_distance = v as f32;
        }
        if let Some(v) = o.get_str("add_points_frame") {
            s.points_frame = PointsFrame::parse(v).ok_or_else(|| {
                StageError::Options(format!(
                    "stage 'train' option 'add_points_frame': unknown frame '{v}' (use colmap \
                     or scene)"
                ))
            })?;
        }
        if let Some(v) = fraction("lambda_dssim", 1.0)? {
            s.lambda_dssim = v;
        }
        if let Some(v) = o.get_f64("position_lr") {
            if !(v.is_finite() && v > 0.0 && v <= 1.0) {
                return Err(StageError::Options(format!(
                    "stage 'train' option 'position_lr' must be in (0, 1], got {v}"
                )));
            }
            // The presets decay it 100× over the run.
            s.position_lr = [v, v / 100.0];
        }
        if let Some(v) = o.get_str("scene_scale") {
            s.scale = parse_scale(v)?;
        }
        Ok(s)
    }

    /// The scene scale for these cameras and initial points.
    pub fn scene_scale(&self, cameras: &[Camera], points: &[[f32; 3]]) -> Result<f64, String> {
        match self.scale {
            ScaleRule::CameraExtent => scene_extent(cameras),
            ScaleRule::Depth => depth_scene_scale(cameras, points),
            ScaleRule::Fixed(v) => Ok(v),
        }
        .map_err(|e| e.to_string())
    }

    /// Everything the run used, for the summary and the scene history.
    pub fn record(&self, scene_scale: f64) -> Value {
        let d = &self.densify;
        let rule = match self.scale {
            ScaleRule::CameraExtent => "extent",
            ScaleRule::Depth => "depth",
            ScaleRule::Fixed(_) => "given",
        };
        // Through the shortest decimal form, so 2e-4 reads 0.0002 and not 0.000199999995.
        let tidy = |v: f32| -> f64 { v.to_string().parse().unwrap_or(f64::from(v)) };
        json!({
            "preset": self.preset,
            "scene_scale": scene_scale,
            "scene_scale_rule": rule,
            "densify_from": d.from_iter,
            "densify_until": d.until_iter,
            "densify_every": d.interval,
            "densify_grad": tidy(d.grad_threshold),
            "percent_dense": tidy(d.percent_dense),
            "prune_opacity": tidy(d.min_opacity),
            "prune_large": tidy(d.prune_large),
            "opacity_reset_every": d.opacity_reset_interval,
            "depth_prune_range": tidy(d.depth_prune_range),
            "add_points_at": d.add_points_at,
            "add_points_count": d.add_points_count,
            "add_points_distance": tidy(d.add_points_distance),
            "add_points_frame": self.points_frame.name(),
            "sh_every": self.sh_interval,
            "lambda_dssim": tidy(self.lambda_dssim),
            "position_lr": self.position_lr,
        })
    }
}

/// `extent`, `depth` or a positive length.
fn parse_scale(v: &str) -> Result<ScaleRule, StageError> {
    match v {
        "extent" => Ok(ScaleRule::CameraExtent),
        "depth" => Ok(ScaleRule::Depth),
        _ => match v.parse::<f64>() {
            Ok(x) if x.is_finite() && x > 0.0 => Ok(ScaleRule::Fixed(x)),
            _ => Err(StageError::Options(format!(
                "stage 'train' option 'scene_scale': expected extent, depth or a positive \
                 length in scene units, got '{v}'"
            ))),
        },
    }
}

/// The options that override the preset; absent ones take the preset's value.
pub fn options() -> Vec<OptionSpec> {
    let int = |name: &str, help: &str| OptionSpec::optional(name, OptionKind::Int, help);
    let float = |name: &str, help: &str| OptionSpec::optional(name, OptionKind::Float, help);
    let string = |name: &str, help: &str| OptionSpec::optional(name, OptionKind::String, help);
    vec![
        OptionSpec::optional(
            "schedule",
            OptionKind::String,
            "density-control preset: auto (INRIA's rules without the large-Gaussian prune, \
             which deletes the background of forward-facing captures; 3dgs's default), deblur \
             (CoCoGaussian's released code: no opacity reset, depth-weighted pruning, densify \
             until 20000, point addition at 2500, λ 0.25, position lr 3.2e-4; cocog's default) or inria (the original \
             rules exactly)",
        )
        .one_of(&["auto", "deblur", "inria"]),
        string(
            "scene_scale",
            "what the position learning rate and the world-space rules scale with: extent \
             (INRIA's camera extent), depth (max of extent and the points' median depth), or a \
             length in scene units (extent)",
        ),
        int("densify_from", "densify after this iteration (500)"),
        int(
            "densify_until",
            "densify and reset opacity before this iteration (auto, inria 15000; deblur 20000)",
        ),
        int("densify_every", "iterations between densifications (100)"),
        float(
            "densify_grad",
            "mean view-space gradient at which a Gaussian is cloned or split (0.0002)",
        ),
        float(
            "percent_dense",
            "largest scale, × scene scale, of a Gaussian that is cloned rather than split (0.01)",
        ),
        float(
            "prune_opacity",
            "prune Gaussians below this opacity (0.005)",
        ),
        float(
            "prune_large",
            "prune Gaussians larger than this × scene scale, after the first opacity reset; \
             0 off (auto 0, inria 0.1)",
        ),
        int(
            "opacity_reset_every",
            "clamp all opacities to 0.01 every N iterations while densifying; 0 never (auto, \
             inria 3000; deblur 0)",
        ),
        int("sh_every", "raise the SH degree every N iterations (1000)"),
        float(
            "depth_prune_range",
            "divide the prune threshold by up to this for the farthest Gaussians (Deblurring \
             3DGS; 1 uniform; auto 1, deblur 3)",
        ),
        int(
            "add_points_at",
            "Deblurring 3DGS's point addition at this iteration (the released CoCoGaussian: \
             2500): up to add_points_max candidates in the robust box of the Gaussians, each \
             coloured from its 4 nearest within add_points_distance, then every Gaussian \
             re-initialised (neighbour scale, opacity 0.1); 0 never (auto and inria 0, deblur \
             2500)",
        ),
        int(
            "add_points_max",
            "most points the addition draws; it draws min(this, initial cloud box volume / \
             1.1³) (200000)",
        ),
        float(
            "add_points_distance",
            "candidates with no Gaussian this close are dropped (2.0 in add_points_frame's \
             units; given, in scene units)",
        ),
        string(
            "add_points_frame",
            "the units the point addition's volume rule and distance are read in: colmap (the \
             frame COLMAP's mapper leaves a reconstruction in, camera centres' robust box 10 \
             across: the released code's data, where it adds about 200k points) or scene (this \
             scene's own units; in metres it adds a handful) (scene)",
        )
        .one_of(&["colmap", "scene"]),
        float(
            "lambda_dssim",
            "weight of D-SSIM in the loss (auto 0.2, deblur 0.25)",
        ),
        float(
            "position_lr",
            "initial position learning rate × scene scale, decayed 100× over the run (auto \
             1.6e-4, deblur 3.2e-4)",
        ),
    ]
}

#[cfg(test)]
mod tests {
    use std::path::PathBuf;

    use cocog_pipeline::Options;
    use serde_json::Map;

    use super::*;

    fn request(given: Value) -> Result<StageRequest, StageError> {
        let given: Map<String, Value> = serde_json::from_value(given).unwrap();
        Ok(StageRequest {
            input: PathBuf::new(),
            output: PathBuf::new(),
            options: Options::validate("train", &options(), &given)?,
        })
    }

    #[test]
    fn inria_preset_is_the_original_rules_and_auto_drops_only_the_large_prune() {
        let inria = Schedule::from_request(&request(json!({"schedule": "inria"})).unwrap(), "3dgs");
        let inria = inria.unwrap();
        assert_eq!(inria.densify, DensifyConfig::default());
        assert_eq!(inria.scale, ScaleRule::CameraExtent);
        assert_eq!(inria.sh_interval, 1000);
        // Plain 3DGS gets `auto`; the default method, cocog, gets `deblur`.
        let auto = Schedule::from_request(&request(json!({})).unwrap(), "3dgs").unwrap();
        assert_eq!(auto.preset, "auto");
        let deblur = Schedule::from_request(&request(json!({})).unwrap(), "cocog").unwrap();
        assert_eq!(deblur.preset, "deblur");
        assert_eq!(auto.scale, ScaleRule::CameraExtent);
        let expect = DensifyConfig {
            prune_large: 0.0,
            ..DensifyConfig::default()
        };
        assert_eq!(auto.densify, expect);
        let depth = request(json!({"scene_scale": "depth"})).unwrap();
        assert_eq!(
            Schedule::from_request(&depth, "3dgs").unwrap().scale,
            ScaleRule::Depth
        );
    }

    #[test]
    fn every_override_lands_and_is_recorded() {
        let req = request(json!({
            "schedule": "inria", "scene_scale": "2.5", "densify_from": 10, "densify_until": 90,
            "densify_every": 7, "densify_grad": 1e-3, "percent_dense": 0.02,
            "prune_opacity": 0.01, "prune_large": 0.0, "opacity_reset_every": 0, "sh_every": 50,
        }))
        .unwrap();
        let s = Schedule::from_request(&req, "3dgs").unwrap();
        let r = s.record(2.5);
        for (key, want) in [
            ("densify_from", 10.0),
            ("densify_until", 90.0),
            ("densify_every", 7.0),
            ("densify_grad", 1e-3),
            ("percent_dense", 0.02),
            ("prune_opacity", 0.01),
            ("prune_large", 0.0),
            ("opacity_reset_every", 0.0),
            ("sh_every", 50.0),
            ("scene_scale", 2.5),
        ] {
            let got = r[key].as_f64().unwrap();
            assert!(
                (got - want).abs() <= 1e-9 * want.max(1.0),
                "{key}: {got} vs {want}"
            );
        }
        assert_eq!(r["scene_scale_rule"], "given");
        assert_eq!(r["add_points_frame"], "scene");
        assert!(!s.densify.resets_opacity_at(3000));
        let colmap = request(json!({"add_points_frame": "colmap"})).unwrap();
        let s = Schedule::from_request(&colmap, "cocog").unwrap();
        assert_eq!(s.record(1.0)["add_points_frame"], "colmap");
    }

    #[test]
    fn bad_values_are_refused_by_name() {
        for (given, name) in [
            (json!({"schedule": "fast"}), "schedule"),
            (json!({"add_points_frame": "metres"}), "add_points_frame"),
            (json!({"scene_scale": "0"}), "scene_scale"),
            (json!({"scene_scale": "nan"}), "scene_scale"),
            (json!({"scene_scale": "median"}), "scene_scale"),
            (json!({"densify_every": 0}), "densify_every"),
            (json!({"densify_from": -1}), "densify_from"),
            (json!({"prune_opacity": 1.5}), "prune_opacity"),
            (json!({"densify_grad": -1.0}), "densify_grad"),
        ] {
            let err = request(given)
                .and_then(|r| Schedule::from_request(&r, "3dgs"))
                .unwrap_err()
                .to_string();
            assert!(err.contains(name), "{err}");
        }
    }
}
