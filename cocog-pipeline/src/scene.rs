//! The scene directory: `scene.json` plus the files it names.
//!
//! Format `cocog.scene`, version `MAJOR.MINOR`. A reader accepts every minor version of
//! its major (new minors only add optional fields) and refuses other majors by name.
//! Poses are `world_from_camera`, 4×4 row-major, OpenCV camera axes (x right, y down,
//! z forward). Relative paths resolve against the scene directory; ingest stores
//! absolute paths to the dataset's images so scenes can live anywhere.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use serde_json::Value;

use crate::atomic;

pub const FORMAT: &str = "cocog.scene";
pub const MAJOR: u32 = 1;
pub const MINOR: u32 = 1;
pub const MANIFEST: &str = "scene.json";

#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{path}: not a valid scene manifest: {source}")]
    Parse {
        path: PathBuf,
        #[source]
        source: serde_json::Error,
    },
    #[error("{path}: {message}")]
    Invalid { path: PathBuf, message: String },
}

/// A pinhole camera. Distorted models are undistorted or refused at ingest.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Camera {
    pub id: u32,
    pub width: u32,
    pub height: u32,
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Split {
    Train,
    Test,
}

/// A thin-lens state for one view: learned by CoCoGaussian, or known (synthetic data).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Lens {
    /// Distance in focus, in scene units (CoCoGaussian measures it from the camera centre;
    /// datasets along the optical axis, which agree at the image centre).
    pub focus_distance: f64,
    /// Diameter of the aperture in scene units, as in the thin lens's circle of confusion
    /// of fx·A·|1/d − 1/d_F| pixels (learned by the lens variant only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub aperture: Option<f64>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct View {
    /// Stable name and sort key: the image name as the dataset lists it (e.g. `000.png`);
    /// `render` names its PNG after this name's stem.
    pub name: String,
    pub image: String,
    pub camera: u32,
    pub world_from_camera: [[f64; 4]; 4],
    pub split: Split,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lens: Option<Lens>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub depth: Option<String>,
}

impl View {
    /// The camera centre in world coordinates: `world_from_camera`'s translation.
    pub fn centre(&self) -> [f64; 3] {
        let m = &self.world_from_camera;
        [m[0][3], m[1][3], m[2][3]]
    }
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Bounds {
    /// Nearest and farthest scene depth over all views (LLFF bounds or from points).
    pub near: f64,
    pub far: f64,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct HistoryEntry {
    pub stage: String,
    /// "built-in" or the plugin file and version that ran.
    pub provider: String,
    pub input: String,
    pub options: Value,
    /// What the stage made of its options where that depends on the input (e.g. train's full
    /// schedule with the scene scale it derived), so the history alone reproduces the run.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub resolved: Option<Value>,
    pub cocog_version: String,
    /// Seconds since the Unix epoch.
    pub finished_at: u64,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Scene {
    pub format: String,
    pub version: String,
    pub cameras: Vec<Camera>,
    pub views: Vec<View>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bounds: Option<Bounds>,
    /// World up direction, when known (e.g. from the mean camera up vector).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub up: Option<[f64; 3]>,
    /// Initial point cloud (xyz + rgb PLY), relative to the scene dir.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub points: Option<String>,
    /// Trained Gaussians (INRIA 3DGS PLY), relative to the scene dir.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gaussians: Option<String>,
    /// CoCoGaussian's lens model (`lens-model.safetensors`: h_θ, F, learned focus distances),
    /// which refocused renders need; since 1.1.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lens_model: Option<String>,
    #[serde(default)]
    pub history: Vec<HistoryEntry>,
}

impl Default for Scene {
    fn default() -> Self {
        Self {
            format: FORMAT.to_owned(),
            version: format!("{MAJOR}.{MINOR}"),
            cameras: Vec::new(),
            views: Vec::new(),
            bounds: None,
            up: None,
            points: None,
            gaussians: None,
            lens_model: None,
            history: Vec::new(),
        }
    }
}

impl Scene {
    /// Reads and validates `dir/scene.json`.
    pub fn load(dir: &Path) -> Result<Self, SceneError> {
        let path = dir.join(MANIFEST);
        let text = std::fs::read_to_string(&path).map_err(|source| SceneError::Io {
            path: path.clone(),
            source,
        })?;
        // Check format and version before the full parse, so a newer manifest gets a
        // version error rather than a confusing missing-field error.
        let raw: Value = serde_json::from_str(&text).map_err(|source| SceneError::Parse {
            path: path.clone(),
            source,
        })?;
        check_header(&path, &raw)?;
        // From the text again, not from `raw`: serde_json then says the line and column.
        let scene: Self = serde_json::from_str(&text).map_err(|source| SceneError::Parse {
            path: path.clone(),
            source,
        })?;
        scene
            .validate()
            .map_err(|message| SceneError::Invalid { path, message })?;
        Ok(scene)
    }

    /// Writes `dir/scene.json` atomically (temp file, then rename).
    pub fn save(&self, dir: &Path) -> Result<(), SceneError> {
        let path = dir.join(MANIFEST);
        self.validate().map_err(|message| SceneError::Invalid {
            path: path.clone(),
            message,
        })?;
        let mut text = serde_json::to_string_pretty(self).map_err(|source| SceneError::Parse {
            path: path.clone(),
            source,
        })?;
        text.push('\n');
        atomic::write(&path, text.as_bytes()).map_err(|source| SceneError::Io { path, source })
    }

    /// Resolves a path stored in the manifest against the scene directory.
    pub fn resolve(dir: &Path, stored: &str) -> PathBuf {
        let p = Path::new(stored);
        if p.is_absolute() {
            p.to_path_buf()
        } else {
            dir.join(p)
        }
    }

    /// Makes every relative path in the manifest absolute against `dir` (the scene's own
    /// directory), so the scene stays valid when a stage writes it somewhere else.
    pub fn rebase(&mut self, dir: &Path) -> Result<(), SceneError> {
        let dir = dir.canonicalize().map_err(|source| SceneError::Io {
            path: dir.to_path_buf(),
            source,
        })?;
        for p in self.paths_mut() {
            *p = Self::resolve(&dir, p).display().to_string();
        }
        Ok(())
    }

    /// Every file path the manifest names: the models, then each view's photo and depth map.
    /// Code that resolves or protects a scene's files goes through here, so a new path field
    /// cannot be missed by one of them.
    pub fn paths(&self) -> impl Iterator<Item = &String> {
        let views = self
            .views
            .iter()
            .flat_map(|v| std::iter::once(&v.image).chain(v.depth.as_ref()));
        [&self.points, &self.gaussians, &self.lens_model]
            .into_iter()
            .flatten()
            .chain(views)
    }

    /// `paths`, to rewrite them.
    pub fn paths_mut(&mut self) -> impl Iterator<Item = &mut String> {
        let views = self.views.iter_mut().flat_map(|v| {
            let View { image, depth, .. } = v;
            std::iter::once(image).chain(depth.as_mut())
        });
        [&mut self.points, &mut self.gaussians, &mut self.lens_model]
            .into_iter()
            .flatten()
            .chain(views)
    }

    /// The colour the last training run composited photos over and rendered its Gaussians
    /// over (train's resolved `background`), which renders and scores must reuse.
    pub fn trained_background(&self) -> Option<[f32; 3]> {
        let entry = self.history.iter().rev().find(|h| h.stage == "train")?;
        let rgb = entry.resolved.as_ref()?.get("background")?.as_array()?;
        let rgb: Vec<f32> = rgb
            .iter()
            .filter_map(|v| Some(v.as_f64()? as f32))
            .collect();
        <[f32; 3]>::try_from(rgb).ok()
    }

    pub fn camera(&self, id: u32) -> Option<&Camera> {
        self.cameras.iter().find(|c| c.id == id)
    }

    pub fn views_in(&self, split: Split) -> impl Iterator<Item = &View> {
        self.views.iter().filter(move |v| v.split == split)
    }

    /// Checks internal consistency; the message names the offending field.
    pub fn validate(&self) -> Result<(), String> {
        for (i, c) in self.cameras.iter().enumerate() {
            let finite = [c.fx, c.fy, c.cx, c.cy].iter().all(|v| v.is_finite());
            if !finite || c.fx <= 0.0 || c.fy <= 0.0 || c.width == 0 || c.height == 0 {
                return Err(format!(
                    "cameras[{i}] (id {}): expected positive size and finite positive focal lengths",
                    c.id
                ));
            }
            if self.cameras[..i].iter().any(|o| o.id == c.id) {
                return Err(format!("cameras[{i}]: duplicate camera id {}", c.id));
            }
        }
        for (i, v) in self.views.iter().enumerate() {
            if self.camera(v.camera).is_none() {
                return Err(format!(
                    "views[{i}] ({}): camera {} is not in `cameras`",
                    v.name, v.camera
                ));
            }
            check_pose(&v.world_from_camera)
                .map_err(|m| format!("views[{i}] ({}).world_from_camera: {m}", v.name))?;
            if let Some(l) = &v.lens
                && !(l.focus_distance.is_finite() && l.focus_distance > 0.0)
            {
                return Err(format!(
                    "views[{i}] ({}).lens.focus_distance: expected a positive finite distance, got {}",
                    v.name, l.focus_distance
                ));
            }
        }
        if let Some(b) = &self.bounds
            && !(b.near.is_finite() && b.far.is_finite() && b.near < b.far)
        {
            return Err(format!(
                "bounds: expected finite near < far, got near {} far {}",
                b.near, b.far
            ));
        }
        Ok(())
    }
}

fn check_header(path: &Path, raw: &Value) -> Result<(), SceneError> {
    let invalid = |message: String| SceneError::Invalid {
        path: path.to_path_buf(),
        message,
    };
    let format = raw.get("format").and_then(Value::as_str);
    if format != Some(FORMAT) {
        return Err(invalid(format!(
            "field `format`: expected \"{FORMAT}\", found {}",
            format.map_or("nothing".to_owned(), |f| format!("\"{f}\""))
        )));
    }
    let version = raw.get("version").and_then(Value::as_str).unwrap_or("");
    let major = version
        .split('.')
        .next()
        .and_then(|m| m.parse::<u32>().ok());
    match major {
        Some(MAJOR) => Ok(()),
        Some(m) => Err(invalid(format!(
            "manifest version {version} (major {m}) is not supported: this cocog reads {MAJOR}.x"
        ))),
        None => Err(invalid(format!(
            "field `version`: expected \"MAJOR.MINOR\", found \"{version}\""
        ))),
    }
}

/// Whether `m` is a rigid pose: finite, last row [0, 0, 0, 1], orthonormal rotation; the
/// message says what is wrong.
pub fn check_pose(m: &[[f64; 4]; 4]) -> Result<(), String> {
    if m.iter().flatten().any(|v| !v.is_finite()) {
        return Err("contains NaN or infinite values".to_owned());
    }
    if m[3] != [0.0, 0.0, 0.0, 1.0] {
        return Err(format!("last row must be [0, 0, 0, 1], got {:?}", m[3]));
    }
    // R·Rᵀ = I within a tolerance loose enough for f32 round trips.
    for i in 0..3 {
        for j in 0..3 {
            let dot: f64 = (0..3).map(|k| m[i][k] * m[j][k]).sum();
            let want = if i == j { 1.0 } else { 0.0 };
            if (dot - want).abs() > 1e-4 {
                return Err("rotation part is not orthonormal".to_owned());
            }
        }
    }
    Ok(())
}

#[cfg(test)]
#[path = "scene_tests.rs"]
mod tests;
