//! The options of `ingest-photos` and their defaults. The SIFT and matching defaults were
//! chosen by measurement on the defocus dev scenes (BENCHMARKS.md, "ingest photos").

use std::path::PathBuf;

use cocog_pipeline::{OptionKind, OptionSpec, StageError, StageRequest};
use serde_json::Value;

/// Exhaustive matching compares every pair: quadratic, fine up to a few hundred photos.
const EXHAUSTIVE_UP_TO: usize = 300;

const CAMERA_MODELS: [&str; 5] = [
    "SIMPLE_PINHOLE",
    "PINHOLE",
    "SIMPLE_RADIAL",
    "RADIAL",
    "OPENCV",
];

#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Matcher {
    Auto,
    Exhaustive,
    Sequential,
    VocabTree,
}

impl Matcher {
    /// `auto`: exhaustive up to [`EXHAUSTIVE_UP_TO`] photos, then a vocabulary tree when one
    /// is given, else sequential (which assumes the photos were taken in name order).
    pub fn resolve(self, photos: usize, have_tree: bool) -> Self {
        match self {
            Self::Auto if photos <= EXHAUSTIVE_UP_TO => Self::Exhaustive,
            Self::Auto if have_tree => Self::VocabTree,
            Self::Auto => Self::Sequential,
            m => m,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Self::Auto => "auto",
            Self::Exhaustive => "exhaustive",
            Self::Sequential => "sequential",
            Self::VocabTree => "vocab-tree",
        }
    }

    pub fn command(self) -> &'static str {
        match self {
            Self::Auto | Self::Exhaustive => "exhaustive_matcher",
            Self::Sequential => "sequential_matcher",
            Self::VocabTree => "vocab_tree_matcher",
        }
    }
}

pub(crate) struct PhotoSettings {
    pub colmap: Option<PathBuf>,
    pub matcher: Matcher,
    pub vocab_tree: Option<PathBuf>,
    pub camera_model: String,
    pub camera_per_image: bool,
    pub max_features: i64,
    pub dsp: bool,
    pub max_ratio: f64,
    pub guided: bool,
    pub gpu: bool,
    pub narrow_baseline: bool,
    pub free_intrinsics: bool,
    pub focal_factor: Option<f64>,
    pub min_registered: Option<usize>,
    pub log: Option<PathBuf>,
}

/// Defaults; see the module comment.
const MAX_FEATURES: i64 = 8192;
const DSP: bool = true;
const MAX_RATIO: f64 = 0.8;
const GUIDED: bool = false;
const NARROW_BASELINE: bool = true;

pub(crate) fn options() -> Vec<OptionSpec> {
    vec![
        OptionSpec::optional(
            "colmap",
            OptionKind::Path,
            "the COLMAP program (default: `colmap` on PATH)",
        ),
        OptionSpec::string(
            "matcher",
            "auto",
            "auto (exhaustive up to 300 photos, else vocab-tree with --vocab-tree, else \
             sequential), exhaustive, sequential (photos in capture order), vocab-tree",
        ),
        OptionSpec::optional(
            "vocab-tree",
            OptionKind::Path,
            "COLMAP vocabulary tree file for --matcher vocab-tree",
        ),
        OptionSpec::string(
            "camera-model",
            "SIMPLE_RADIAL",
            "COLMAP camera model to fit: SIMPLE_PINHOLE, PINHOLE, SIMPLE_RADIAL, RADIAL, OPENCV",
        ),
        OptionSpec::bool(
            "camera-per-image",
            false,
            "fit one camera per photo (zoom lenses, mixed cameras) instead of one shared camera",
        ),
        OptionSpec::int(
            "max-features",
            MAX_FEATURES,
            "SIFT features per photo at most",
        )
        .at_least(100.0),
        OptionSpec::bool(
            "dsp",
            DSP,
            "domain-size pooling: SIFT descriptors pooled over several scales, more robust \
             to defocus blur (CPU extraction only)",
        ),
        OptionSpec::float(
            "max-ratio",
            MAX_RATIO,
            "Lowe's ratio test for SIFT matches (higher = looser)",
        )
        .between(0.1, 1.0),
        OptionSpec::bool(
            "guided-matching",
            GUIDED,
            "re-match each pair guided by its two-view geometry",
        ),
        OptionSpec::bool(
            "narrow-baseline",
            NARROW_BASELINE,
            "map with triangulation angles suited to forward-facing captures (cameras a few \
             cm apart): start from pairs at 2° instead of 16°, keep points seen at 0.5°",
        ),
        OptionSpec::bool(
            "free-intrinsics",
            false,
            "let COLMAP's mapper refine the focal length from the first pair on (its own \
             behaviour) instead of holding it at the prior (EXIF, else 1.2 × the longer side) \
             until every photo is in and refining it with the distortion in one final bundle \
             adjustment; held is far more reliable on narrow, defocused captures",
        ),
        OptionSpec::optional(
            "focal-factor",
            OptionKind::Float,
            "focal length prior for photos without EXIF, × the longer side (COLMAP's default \
             1.2 ≈ a 43 mm lens on full frame; a phone's main camera ≈ 0.8). The mapper holds \
             the focal length at its prior, so a prior far off costs accuracy",
        ),
        OptionSpec::bool(
            "gpu",
            false,
            "let COLMAP use its GPU SIFT (needs a CUDA or OpenGL build of COLMAP)",
        ),
        OptionSpec::optional(
            "log",
            OptionKind::Path,
            "where COLMAP's log is written while it runs; moved to colmap/colmap.log in the \
             output on success, left in place on failure (the CLI puts it beside the output)",
        ),
        OptionSpec::optional(
            "min-registered",
            OptionKind::Int,
            "fail unless at least this many photos register (default: half, at least 3)",
        ),
    ]
}

impl PhotoSettings {
    pub fn from_request(req: &StageRequest) -> Result<Self, StageError> {
        let o = &req.options;
        let bad = |name: &str, want: &str, got: &Value| {
            StageError::Options(format!(
                "stage 'ingest-photos' option '{name}': expected {want}, got {got}"
            ))
        };
        let matcher = match o.get_str("matcher").unwrap_or("auto") {
            "auto" => Matcher::Auto,
            "exhaustive" => Matcher::Exhaustive,
            "sequential" => Matcher::Sequential,
            "vocab-tree" => Matcher::VocabTree,
            other => {
                return Err(bad(
                    "matcher",
                    "auto, exhaustive, sequential or vocab-tree",
                    &Value::from(other),
                ));
            }
        };
        let vocab_tree = o.get_path("vocab-tree");
        if matcher == Matcher::VocabTree && vocab_tree.is_none() {
            return Err(StageError::Options(
                "stage 'ingest-photos': --matcher vocab-tree needs --vocab-tree FILE (COLMAP's \
                 vocabulary trees: https://demuc.de/colmap/)"
                    .into(),
            ));
        }
        if let Some(tree) = vocab_tree.as_ref().filter(|t| !t.is_file()) {
            return Err(StageError::Input(format!(
                "{}: vocabulary tree file does not exist",
                tree.display()
            )));
        }
        let camera_model = o
            .get_str("camera-model")
            .unwrap_or("SIMPLE_RADIAL")
            .to_owned();
        if !CAMERA_MODELS.contains(&camera_model.as_str()) {
            return Err(bad(
                "camera-model",
                &CAMERA_MODELS.join(", "),
                &Value::from(camera_model),
            ));
        }
        let min_registered = match o.get("min-registered") {
            None | Some(Value::Null) => None,
            Some(v) => Some(
                v.as_u64()
                    .filter(|n| *n >= 1)
                    .ok_or_else(|| bad("min-registered", "an integer ≥ 1", v))?
                    as usize,
            ),
        };
        let focal_factor = match o.get("focal-factor") {
            None | Some(Value::Null) => None,
            Some(v) => Some(
                v.as_f64()
                    .filter(|f| f.is_finite() && (0.1..=10.0).contains(f))
                    .ok_or_else(|| bad("focal-factor", "a number from 0.1 to 10", v))?,
            ),
        };
        Ok(Self {
            colmap: o.get_path("colmap"),
            matcher,
            vocab_tree,
            camera_model,
            camera_per_image: o.get_bool("camera-per-image").unwrap_or(false),
            max_features: o.get_i64("max-features").unwrap_or(MAX_FEATURES),
            dsp: o.get_bool("dsp").unwrap_or(DSP),
            max_ratio: o.get_f64("max-ratio").unwrap_or(MAX_RATIO),
            guided: o.get_bool("guided-matching").unwrap_or(GUIDED),
            gpu: o.get_bool("gpu").unwrap_or(false),
            narrow_baseline: o.get_bool("narrow-baseline").unwrap_or(NARROW_BASELINE),
            free_intrinsics: o.get_bool("free-intrinsics").unwrap_or(false),
            focal_factor,
            min_registered,
            log: o.get_path("log"),
        })
    }
}
