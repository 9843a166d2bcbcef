use std::path::PathBuf;

/// Everything that can go wrong while scoring images. Each variant names the file (and, where it
/// applies, the field) so a user can fix the input without reading the source.
#[derive(Debug, thiserror::Error)]
pub enum MetricsError {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{path}: cannot decode image: {source}")]
    Decode {
        path: PathBuf,
        #[source]
        source: image::ImageError,
    },
    /// The image decoded but its pixel format is one we refuse (e.g. translucent alpha).
    #[error("{path}: unsupported image: {reason}")]
    Unsupported { path: PathBuf, reason: String },
    #[error(
        "{pred} is {pw}x{ph} but its ground truth {gt} is {gw}x{gh}: \
         predictions must be rendered at the ground-truth resolution"
    )]
    SizeMismatch {
        pred: PathBuf,
        gt: PathBuf,
        pw: u32,
        ph: u32,
        gw: u32,
        gh: u32,
    },
    /// A folder pairing problem: missing match, duplicate stem, empty folder.
    #[error("{path}: {reason}")]
    Pairing { path: PathBuf, reason: String },
    #[error("{path}: image is {width}x{height}; {metric} needs at least {min}x{min}")]
    TooSmall {
        path: PathBuf,
        width: u32,
        height: u32,
        metric: &'static str,
        min: u32,
    },
    /// The LPIPS weights file is present but not what we expect.
    #[error("{path}: bad LPIPS weights: {reason}")]
    Weights { path: PathBuf, reason: String },
    #[error(
        "LPIPS weights for {net} not found (looked in: {searched}); \
         run scripts/lpips/fetch-weights.sh or set COCOG_LPIPS_WEIGHTS to the folder holding \
         {net}.safetensors"
    )]
    WeightsNotFound { net: &'static str, searched: String },
    #[error("cancelled")]
    Cancelled,
    /// Writing the output file failed.
    #[error("{path}: cannot write: {source}")]
    Write {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
}
