//! LPIPS v0.1 (Zhang et al. 2018) on the CPU: the official `lpips.LPIPS(net=...)` forward pass
//! with inputs in [−1,1] — scale, backbone, unit-normalise each tap over channels, squared
//! difference, 1×1 linear layer, spatial mean, sum over the five taps.

mod net;
mod tensor;
mod weights;

use std::path::{Path, PathBuf};

pub use net::Net;
pub use weights::{WEIGHTS_ENV, find_weights, find_weights_in, weights_dirs};

use self::net::{Op, SCALE, SHIFT};
use self::tensor::{Conv, Tensor};
use crate::{FloatImage, MetricsError};

/// LPIPS' `normalize_tensor` epsilon, added to the channel norm before dividing.
const NORM_EPS: f64 = 1e-10;

/// A loaded LPIPS model, cheap to share between threads (`&self` everywhere).
pub struct Lpips {
    net: Net,
    path: PathBuf,
    weights: weights::NetWeights,
    threads: usize,
}

impl Lpips {
    /// Loads `net`'s weights from the first weights folder that has them (see [`weights_dirs`]).
    pub fn load(net: Net) -> Result<Self, MetricsError> {
        Self::from_file(&find_weights(net)?, net)
    }

    /// Loads `net`'s weights from the folder `dir` only.
    pub fn load_from_dir(dir: &Path, net: Net) -> Result<Self, MetricsError> {
        Self::from_file(&find_weights_in(&[dir.to_path_buf()], net)?, net)
    }

    /// Loads a specific converted weights file.
    pub fn from_file(path: &Path, net: Net) -> Result<Self, MetricsError> {
        Ok(Self {
            net,
            path: path.to_path_buf(),
            weights: weights::load(path, net)?,
            threads: std::thread::available_parallelism().map_or(1, |n| n.get()),
        })
    }

    /// Worker threads per convolution (default: all cores; 0 means the default).
    pub fn with_threads(mut self, threads: usize) -> Self {
        if threads > 0 {
            self.threads = threads;
        }
        self
    }

    pub fn net(&self) -> Net {
        self.net
    }

    pub fn weights_path(&self) -> &Path {
        &self.path
    }

    /// The smallest square image side the backbone's windows fit.
    pub fn min_side(&self) -> u32 {
        self.net.min_side() as u32
    }

    /// LPIPS distance between two same-size images on [0,1]; `None` when the image is too small
    /// for the backbone (see [`Lpips::min_side`]).
    pub fn distance(&self, a: &FloatImage, b: &FloatImage) -> Option<f64> {
        assert_eq!(
            (a.width, a.height),
            (b.width, b.height),
            "lpips: size mismatch"
        );
        if !self.net.fits(a.height as usize, a.width as usize) {
            return None;
        }
        let fa = self.features(a);
        let fb = self.features(b);
        let mut total = 0.0;
        for ((ta, tb), lin) in fa.iter().zip(&fb).zip(&self.weights.lins) {
            total += tap_distance(ta, tb, lin);
        }
        Some(total)
    }

    /// The five ReLU taps of the backbone for one image.
    fn features(&self, img: &FloatImage) -> Vec<Tensor> {
        let data = img
            .data
            .chunks_exact(3)
            .flat_map(|px| (0..3).map(move |c| ((2.0 * px[c] - 1.0) as f32 - SHIFT[c]) / SCALE[c]))
            .collect();
        let mut x = Tensor {
            h: img.height as usize,
            w: img.width as usize,
            c: 3,
            data,
        };
        let mut convs = self.weights.convs.iter();
        let mut taps = Vec::with_capacity(5);
        for op in self.net.ops() {
            match *op {
                Op::Conv {
                    k,
                    stride,
                    pad,
                    cout,
                } => {
                    let w = convs.next().expect("weights validated against the table");
                    let conv = Conv {
                        kernel: &w.kernel,
                        bias: &w.bias,
                        k,
                        stride,
                        pad,
                        cout,
                    };
                    x = tensor::conv_relu(&x, &conv, self.threads);
                }
                Op::MaxPool { k, stride } => x = tensor::max_pool(&x, k, stride),
                Op::Tap => taps.push(x.clone()),
            }
        }
        taps
    }
}

/// One tap's term: spatial mean of `Σ_c lin_c · (â_c − b̂_c)²` with â, b̂ unit-normalised over
/// channels. Accumulated in f64 so the spatial mean adds no error of its own.
fn tap_distance(a: &Tensor, b: &Tensor, lin: &[f32]) -> f64 {
    let mut sum = 0.0f64;
    for (pa, pb) in a.data.chunks_exact(a.c).zip(b.data.chunks_exact(b.c)) {
        let norm = |p: &[f32]| p.iter().map(|&v| f64::from(v).powi(2)).sum::<f64>().sqrt();
        let (ia, ib) = (1.0 / (norm(pa) + NORM_EPS), 1.0 / (norm(pb) + NORM_EPS));
        let mut d = 0.0;
        for ((&va, &vb), &w) in pa.iter().zip(pb).zip(lin) {
            let diff = f64::from(va) * ia - f64::from(vb) * ib;
            d += f64::from(w) * diff * diff;
        }
        sum += d;
    }
    sum / (a.h * a.w) as f64
}
