//! f64 CPU reference of the compositor F and the softmax compositing (method.md §5), the
//! oracle of the GPU kernels and what the finite-difference tests differentiate.
//!
//! Tensors are `[image][channel][y][x]`; the renders are `images × 3` channels (RGB).

// Index loops mirror the convolution sums.
#![allow(clippy::needless_range_loop)]

use super::layout::{CompositorLayout, IN_EPS};

/// A stack of `images` feature maps of `channels` × `height` × `width`.
#[derive(Clone, Debug, PartialEq)]
pub struct Maps {
    pub images: usize,
    pub channels: usize,
    pub height: usize,
    pub width: usize,
    pub data: Vec<f64>,
}

impl Maps {
    pub fn zeros(images: usize, channels: usize, height: usize, width: usize) -> Self {
        Self {
            images,
            channels,
            height,
            width,
            data: vec![0.0; images * channels * height * width],
        }
    }

    pub fn at(&self, i: usize, c: usize, y: usize, x: usize) -> f64 {
        self.data[((i * self.channels + c) * self.height + y) * self.width + x]
    }

    fn at_mut(&mut self, i: usize, c: usize, y: usize, x: usize) -> &mut f64 {
        &mut self.data[((i * self.channels + c) * self.height + y) * self.width + x]
    }

    /// Zero outside the image (the convolutions' zero padding).
    fn padded(&self, i: usize, c: usize, y: isize, x: isize) -> f64 {
        if y < 0 || x < 0 || y >= self.height as isize || x >= self.width as isize {
            0.0
        } else {
            self.at(i, c, y as usize, x as usize)
        }
    }
}

/// One convolution's place in the parameters: (in, out, kernel, weight offset, bias offset).
type Conv = (usize, usize, usize, usize, Option<usize>);

fn conv(p: &[f64], l: Conv, x: &Maps) -> Maps {
    let (cin, cout, k, wo, bo) = l;
    let pad = (k / 2) as isize;
    let mut out = Maps::zeros(x.images, cout, x.height, x.width);
    for i in 0..x.images {
        for co in 0..cout {
            for y in 0..x.height {
                for xx in 0..x.width {
                    let mut s = bo.map_or(0.0, |b| p[b + co]);
                    for ci in 0..cin {
                        for ky in 0..k {
                            for kx in 0..k {
                                let w = p[wo + ((co * cin + ci) * k + ky) * k + kx];
                                let yy = y as isize + ky as isize - pad;
                                let xs = xx as isize + kx as isize - pad;
                                s += w * x.padded(i, ci, yy, xs);
                            }
                        }
                    }
                    *out.at_mut(i, co, y, xx) = s;
                }
            }
        }
    }
    out
}

/// Adds the gradients of a convolution's weights and bias into `v_p`, and Σ|term| of each into
/// `bounds` (the scale of its rounding error in f32), and returns its input's gradient.
fn conv_backward(
    p: &[f64],
    l: Conv,
    x: &Maps,
    v_out: &Maps,
    v_p: &mut [f64],
    bounds: &mut [f64],
) -> Maps {
    let (cin, cout, k, wo, bo) = l;
    let pad = (k / 2) as isize;
    let mut v_x = Maps::zeros(x.images, cin, x.height, x.width);
    for i in 0..x.images {
        for co in 0..cout {
            for y in 0..x.height {
                for xx in 0..x.width {
                    let g = v_out.at(i, co, y, xx);
                    if let Some(b) = bo {
                        v_p[b + co] += g;
                        bounds[b + co] += g.abs();
                    }
                    for ci in 0..cin {
                        for ky in 0..k {
                            for kx in 0..k {
                                let yy = y as isize + ky as isize - pad;
                                let xs = xx as isize + kx as isize - pad;
                                if yy < 0
                                    || xs < 0
                                    || yy >= x.height as isize
                                    || xs >= x.width as isize
                                {
                                    continue;
                                }
                                let w = wo + ((co * cin + ci) * k + ky) * k + kx;
                                let xv = x.at(i, ci, yy as usize, xs as usize);
                                v_p[w] += g * xv;
                                bounds[w] += (g * xv).abs();
                                *v_x.at_mut(i, ci, yy as usize, xs as usize) += g * p[w];
                            }
                        }
                    }
                }
            }
        }
    }
    v_x
}

/// ReLU then instance normalisation (no affine, biased variance): returns the normalised maps
/// and each (image, channel)'s 1/σ.
fn relu_norm(z: &Maps) -> (Maps, Vec<f64>) {
    let hw = (z.height * z.width) as f64;
    let mut y = z.clone();
    let mut rstd = Vec::new();
    for plane in y.data.chunks_mut(z.height * z.width) {
        for v in plane.iter_mut() {
            *v = v.max(0.0);
        }
        let mean = plane.iter().sum::<f64>() / hw;
        let var = plane.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / hw;
        let r = 1.0 / (var + IN_EPS).sqrt();
        for v in plane.iter_mut() {
            *v = (*v - mean) * r;
        }
        rstd.push(r);
    }
    (y, rstd)
}

/// The adjoint of `relu_norm`: ∂/∂a = r·(v − mean(v) − y·mean(v·y)), then the ReLU's mask.
fn relu_norm_backward(z: &Maps, y: &Maps, rstd: &[f64], v_y: &Maps) -> Maps {
    let n = z.height * z.width;
    let mut v_z = v_y.clone();
    for (p, r) in rstd.iter().enumerate() {
        let range = p * n..(p + 1) * n;
        let (yv, gv) = (&y.data[range.clone()], &v_y.data[range.clone()]);
        let m1 = gv.iter().sum::<f64>() / n as f64;
        let m2 = gv.iter().zip(yv).map(|(g, y)| g * y).sum::<f64>() / n as f64;
        for (j, out) in v_z.data[range.clone()].iter_mut().enumerate() {
            let active = z.data[p * n + j] > 0.0;
            *out = if active {
                r * (gv[j] - m1 - yv[j] * m2)
            } else {
                0.0
            };
        }
    }
    v_z
}

/// Everything F's forward computed, for the backward.
#[derive(Clone, Debug)]
pub struct Trace {
    pub renders: Maps,
    z1: Maps,
    y1: Maps,
    r1: Vec<f64>,
    z2: Maps,
    y2: Maps,
    r2: Vec<f64>,
    /// Per pixel, the softmax weight of each image, `[image][y][x]` as a 1-channel stack.
    pub weights: Maps,
    /// The composite, 3 channels, one image.
    pub blend: Maps,
}

fn convs(l: &CompositorLayout) -> [Conv; 3] {
    let c = l.channels;
    [
        (3, c, 5, l.conv1_w, Some(l.conv1_b)),
        (c, c, 3, l.conv2_w, Some(l.conv2_b)),
        (c, 1, 3, l.head_w, None),
    ]
}

/// Softmax over images of `logits`, per pixel, and the weighted sum of `renders`.
pub fn composite(renders: &Maps, logits: &Maps) -> (Maps, Maps) {
    let (n, h, w) = (renders.images, renders.height, renders.width);
    let mut weights = Maps::zeros(n, 1, h, w);
    let mut blend = Maps::zeros(1, 3, h, w);
    for y in 0..h {
        for x in 0..w {
            let top = (0..n)
                .map(|i| logits.at(i, 0, y, x))
                .fold(f64::MIN, f64::max);
            let e: Vec<f64> = (0..n)
                .map(|i| (logits.at(i, 0, y, x) - top).exp())
                .collect();
            let sum: f64 = e.iter().sum();
            for i in 0..n {
                let wi = e[i] / sum;
                *weights.at_mut(i, 0, y, x) = wi;
                for c in 0..3 {
                    *blend.at_mut(0, c, y, x) += wi * renders.at(i, c, y, x);
                }
            }
        }
    }
    (weights, blend)
}

/// F on the renders, then the composite.
pub fn forward(l: &CompositorLayout, p: &[f64], renders: &Maps) -> Trace {
    let [c1, c2, _] = convs(l);
    let z1 = conv(p, c1, renders);
    let y1 = relu_norm(&z1).0;
    let z2 = conv(p, c2, &y1);
    let y2 = relu_norm(&z2).0;
    forward_from_stored(l, p, renders, &[z1, y1, z2, y2])
}

/// F's four stored maps (z1, y1, z2, y2: each layer's pre-activation and normalised output).
pub type Stored = [Maps; 4];

/// Each stored map computed exactly from the stored map before it in `given` (the renders for
/// z1): what a GPU's stored maps must round from, layer by layer.
pub fn stored_from(l: &CompositorLayout, p: &[f64], renders: &Maps, given: &Stored) -> Stored {
    let [c1, c2, _] = convs(l);
    [
        conv(p, c1, renders),
        relu_norm(&given[0]).0,
        conv(p, c2, &given[1]),
        relu_norm(&given[2]).0,
    ]
}

/// The trace of a forward that stored `given` (exact maps, or a GPU's): the statistics and
/// the head computed from them, so its backward is the exact adjoint of that forward.
pub fn forward_from_stored(
    l: &CompositorLayout,
    p: &[f64],
    renders: &Maps,
    given: &Stored,
) -> Trace {
    let [_, _, head] = convs(l);
    let [z1, y1, z2, y2] = given.clone();
    let (r1, r2) = (relu_norm(&z1).1, relu_norm(&z2).1);
    let logits = conv(p, head, &y2);
    let (weights, blend) = composite(renders, &logits);
    Trace {
        renders: renders.clone(),
        z1,
        y1,
        r1,
        z2,
        y2,
        r2,
        weights,
        blend,
    }
}

/// Gradients of the renders (through the product only: F's input is detached) and of the
/// logits, given the composite's.
pub fn composite_backward(
    renders: &Maps,
    weights: &Maps,
    blend: &Maps,
    v_blend: &Maps,
) -> (Maps, Maps) {
    let (n, h, w) = (renders.images, renders.height, renders.width);
    let mut v_renders = Maps::zeros(n, 3, h, w);
    let mut v_logits = Maps::zeros(n, 1, h, w);
    for i in 0..n {
        for y in 0..h {
            for x in 0..w {
                let wi = weights.at(i, 0, y, x);
                let mut dot = 0.0;
                for c in 0..3 {
                    let g = v_blend.at(0, c, y, x);
                    *v_renders.at_mut(i, c, y, x) = wi * g;
                    dot += (renders.at(i, c, y, x) - blend.at(0, c, y, x)) * g;
                }
                *v_logits.at_mut(i, 0, y, x) = wi * dot;
            }
        }
    }
    (v_renders, v_logits)
}

/// F's parameter gradient and the renders', given the composite's.
#[derive(Clone, Debug)]
pub struct Backward {
    pub v_renders: Maps,
    pub v_params: Vec<f64>,
    /// Per parameter, Σ|term| of its gradient's final sum: an f32 implementation's rounding
    /// error scales with this, not with the (possibly cancelled) gradient itself.
    pub bounds: Vec<f64>,
}

pub fn backward(l: &CompositorLayout, p: &[f64], t: &Trace, v_blend: &Maps) -> Backward {
    let [c1, c2, head] = convs(l);
    let (v_renders, v_logits) = composite_backward(&t.renders, &t.weights, &t.blend, v_blend);
    let mut v_p = vec![0.0; l.len];
    let mut bounds = vec![0.0; l.len];
    let v_y2 = conv_backward(p, head, &t.y2, &v_logits, &mut v_p, &mut bounds);
    let v_z2 = relu_norm_backward(&t.z2, &t.y2, &t.r2, &v_y2);
    let v_y1 = conv_backward(p, c2, &t.y1, &v_z2, &mut v_p, &mut bounds);
    let v_z1 = relu_norm_backward(&t.z1, &t.y1, &t.r1, &v_y1);
    conv_backward(p, c1, &t.renders, &v_z1, &mut v_p, &mut bounds);
    Backward {
        v_renders,
        v_params: v_p,
        bounds,
    }
}
