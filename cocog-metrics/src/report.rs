//! Scoring folders of images into the `metrics.json` report.
//!
//! `metrics.json` (format `cocog-metrics`, version 1):
//! - `pred_dir`, `gt_dir`, `count`;
//! - `conventions`: metric name → the exact definition used (only metrics that were computed);
//! - `lpips`: `weights` (net → file used) and `note` (why LPIPS is missing, if it is);
//! - `mean`: the mean of the per-image values of each metric;
//! - `images[]`: `name` (the shared file stem), `pred`, `gt`, `width`, `height`, `psnr`,
//!   `ssim_deblurnerf`, `ssim_gaussian11`, and `lpips_alex` / `lpips_vgg` when computed.
//!
//! PSNR is `null` when infinite (identical images); a mean over such an image is `null` too.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::Serialize;

use crate::lpips::{Lpips, Net};
use crate::pairs::{ImagePair, pair_dirs};
use crate::{MetricsError, SsimConvention, load_image, psnr, ssim};

/// Report format name and version written into every `metrics.json`.
pub const REPORT_FORMAT: &str = "cocog-metrics";
pub const REPORT_VERSION: u32 = 1;

/// What to do about LPIPS.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LpipsMode {
    /// Compute it when the weights are installed; otherwise say how to get them and go on.
    Auto,
    /// Fail when the weights are missing.
    Require,
    Off,
}

#[derive(Debug, Clone)]
pub struct EvalOptions {
    pub lpips: LpipsMode,
    /// Also compute LPIPS-VGG (about 25× the work of AlexNet).
    pub vgg: bool,
    /// Worker threads for LPIPS; 0 = all cores.
    pub threads: usize,
    /// Look for LPIPS weights only here instead of [`crate::weights_dirs`].
    pub weights_dir: Option<PathBuf>,
}

impl Default for EvalOptions {
    fn default() -> Self {
        Self {
            lpips: LpipsMode::Auto,
            vgg: false,
            threads: 0,
            weights_dir: None,
        }
    }
}

/// Progress and cancellation hooks, so a pipeline stage can forward its context.
pub trait Observer {
    fn progress(&self, _done: usize, _total: usize) {}
    fn cancelled(&self) -> bool {
        false
    }
}

impl Observer for () {}

/// Scores of one image pair, or their means. `psnr` is `+inf` (JSON `null`) for identical images.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Scores {
    pub psnr: f64,
    pub ssim_deblurnerf: f64,
    pub ssim_gaussian11: f64,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub lpips_alex: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub lpips_vgg: Option<f64>,
}

#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ImageScores {
    pub name: String,
    pub pred: PathBuf,
    pub gt: PathBuf,
    pub width: u32,
    pub height: u32,
    #[serde(flatten)]
    pub scores: Scores,
}

/// Which LPIPS backbones were used, from which files, and why not when they were not.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LpipsStatus {
    pub weights: BTreeMap<String, PathBuf>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub note: Option<String>,
}

/// The content of `metrics.json`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Report {
    pub format: String,
    pub version: u32,
    pub pred_dir: PathBuf,
    pub gt_dir: PathBuf,
    pub count: usize,
    /// Metric name → the exact convention it follows.
    pub conventions: BTreeMap<String, String>,
    pub lpips: LpipsStatus,
    pub mean: Scores,
    pub images: Vec<ImageScores>,
}

fn conventions(models: &Models) -> BTreeMap<String, String> {
    let mut c = BTreeMap::new();
    let mut put = |k: &str, v: &str| c.insert(k.to_string(), v.to_string());
    put(
        "psnr",
        "10*log10(1/MSE) on [0,1] over all pixels and channels; mean of per-image values",
    );
    put(
        "ssim_deblurnerf",
        "skimage structural_similarity(2a-1, 2b-1, channel_axis=-1, data_range=2): 7x7 uniform \
         window, sample covariance, crop 3 (Deblur-NeRF/CoCoGaussian tables)",
    );
    put(
        "ssim_gaussian11",
        "skimage structural_similarity(a, b, channel_axis=-1, data_range=1, \
         gaussian_weights=True, sigma=1.5, use_sample_covariance=False): Wang et al. 2004",
    );
    let lp = "LPIPS v0.1, inputs 2x-1, linear layers on, spatial mean";
    if models.alex.is_some() {
        put(
            "lpips_alex",
            &format!("{lp}, AlexNet backbone (lpips.LPIPS() default)"),
        );
    }
    if models.vgg.is_some() {
        put("lpips_vgg", &format!("{lp}, VGG-16 backbone"));
    }
    c
}

/// The LPIPS models an evaluation uses.
pub struct Models {
    pub alex: Option<Lpips>,
    pub vgg: Option<Lpips>,
    /// Why LPIPS is (partly) missing, for the report and the user.
    pub note: Option<String>,
}

impl Models {
    pub fn load(opts: &EvalOptions) -> Result<Self, MetricsError> {
        let mut models = Models {
            alex: None,
            vgg: None,
            note: None,
        };
        if opts.lpips == LpipsMode::Off {
            models.note = Some("LPIPS disabled".into());
            return Ok(models);
        }
        let nets: &[Net] = if opts.vgg {
            &[Net::Alex, Net::Vgg]
        } else {
            &[Net::Alex]
        };
        for &net in nets {
            let loaded = match &opts.weights_dir {
                Some(dir) => Lpips::load_from_dir(dir, net),
                None => Lpips::load(net),
            };
            let model = match loaded {
                Ok(m) => m.with_threads(opts.threads),
                // Only absence is tolerated in auto mode; a present but broken file is an error.
                Err(e @ MetricsError::WeightsNotFound { .. }) if opts.lpips == LpipsMode::Auto => {
                    models.note = Some(format!("LPIPS-{} not computed: {e}", net.name()));
                    continue;
                }
                Err(e) => return Err(e),
            };
            match net {
                Net::Alex => models.alex = Some(model),
                Net::Vgg => models.vgg = Some(model),
            }
        }
        Ok(models)
    }

    fn weights(&self) -> BTreeMap<String, PathBuf> {
        [&self.alex, &self.vgg]
            .into_iter()
            .flatten()
            .map(|m| (m.net().name().to_string(), m.weights_path().to_path_buf()))
            .collect()
    }
}

/// Scores one pair: decode both, check sizes, compute every metric.
pub fn score_pair(pair: &ImagePair, models: &Models) -> Result<ImageScores, MetricsError> {
    let pred = load_image(&pair.pred)?;
    let gt = load_image(&pair.gt)?;
    if (pred.width, pred.height) != (gt.width, gt.height) {
        return Err(MetricsError::SizeMismatch {
            pred: pair.pred.clone(),
            gt: pair.gt.clone(),
            pw: pred.width,
            ph: pred.height,
            gw: gt.width,
            gh: gt.height,
        });
    }
    let too_small = |metric, min| MetricsError::TooSmall {
        path: pair.pred.clone(),
        width: pred.width,
        height: pred.height,
        metric,
        min,
    };
    let ssim_of = |conv: SsimConvention| {
        ssim(&pred, &gt, conv).ok_or_else(|| too_small("SSIM", conv.min_side()))
    };
    let lpips_of = |model: &Option<Lpips>| -> Result<Option<f64>, MetricsError> {
        model
            .as_ref()
            .map(|m| {
                m.distance(&pred, &gt)
                    .ok_or_else(|| too_small("LPIPS (disable it with lpips=off)", m.min_side()))
            })
            .transpose()
    };
    Ok(ImageScores {
        name: pair.name.clone(),
        pred: pair.pred.clone(),
        gt: pair.gt.clone(),
        width: pred.width,
        height: pred.height,
        scores: Scores {
            psnr: psnr(&pred, &gt),
            ssim_deblurnerf: ssim_of(SsimConvention::DeblurNerf)?,
            ssim_gaussian11: ssim_of(SsimConvention::Gaussian11)?,
            lpips_alex: lpips_of(&models.alex)?,
            lpips_vgg: lpips_of(&models.vgg)?,
        },
    })
}

fn mean(images: &[ImageScores]) -> Scores {
    let n = images.len() as f64;
    let avg = |f: &dyn Fn(&Scores) -> f64| images.iter().map(|i| f(&i.scores)).sum::<f64>() / n;
    let avg_opt = |f: &dyn Fn(&Scores) -> Option<f64>| {
        images
            .iter()
            .map(|i| f(&i.scores))
            .sum::<Option<f64>>()
            .map(|s| s / n)
    };
    Scores {
        psnr: avg(&|s| s.psnr),
        ssim_deblurnerf: avg(&|s| s.ssim_deblurnerf),
        ssim_gaussian11: avg(&|s| s.ssim_gaussian11),
        lpips_alex: avg_opt(&|s| s.lpips_alex),
        lpips_vgg: avg_opt(&|s| s.lpips_vgg),
    }
}

/// Scores every prediction in `pred_dir` against the same-stem image in `gt_dir`.
pub fn evaluate_dirs(
    pred_dir: &Path,
    gt_dir: &Path,
    opts: &EvalOptions,
    observer: &dyn Observer,
) -> Result<Report, MetricsError> {
    let pairs = pair_dirs(pred_dir, gt_dir)?;
    let models = Models::load(opts)?;
    let mut images = Vec::with_capacity(pairs.len());
    observer.progress(0, pairs.len());
    for (i, pair) in pairs.iter().enumerate() {
        if observer.cancelled() {
            return Err(MetricsError::Cancelled);
        }
        images.push(score_pair(pair, &models)?);
        observer.progress(i + 1, pairs.len());
    }
    Ok(Report {
        format: REPORT_FORMAT.into(),
        version: REPORT_VERSION,
        pred_dir: pred_dir.to_path_buf(),
        gt_dir: gt_dir.to_path_buf(),
        count: images.len(),
        conventions: conventions(&models),
        lpips: LpipsStatus {
            weights: models.weights(),
            note: models.note.clone(),
        },
        mean: mean(&images),
        images,
    })
}

impl Report {
    pub fn to_json(&self) -> serde_json::Value {
        serde_json::to_value(self).expect("report is plain data")
    }
}

/// Writes `value` as pretty JSON to `path` without ever leaving a half-written file: a temporary
/// file in the same folder, then a rename.
pub fn write_json_atomic(path: &Path, value: &serde_json::Value) -> Result<(), MetricsError> {
    let write_err = |source| MetricsError::Write {
        path: path.to_path_buf(),
        source,
    };
    let dir = path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned());
    let tmp = dir.join(format!(
        ".{}.tmp-{}",
        name.unwrap_or_else(|| "metrics.json".into()),
        std::process::id()
    ));
    let mut text = serde_json::to_string_pretty(value).expect("json value serialises");
    text.push('\n');
    let result = std::fs::write(&tmp, text).and_then(|()| std::fs::rename(&tmp, path));
    if result.is_err() {
        // Best effort: the temp file is ours and useless after a failure.
        let _ = std::fs::remove_file(&tmp);
    }
    result.map_err(write_err)
}
