//! The two LPIPS v0.1 backbones as data: the layer sequence, where the five feature taps sit, and
//! the input scaling. The forward pass and the weights loader both walk these tables, so shapes are
//! validated against the very architecture that is executed.

/// A backbone LPIPS can use.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Net {
    /// AlexNet: `lpips.LPIPS()`'s default and what the deblurring papers report.
    Alex,
    /// VGG-16: slower (~25× the work of AlexNet), reported by some other papers.
    Vgg,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Op {
    /// Convolution followed by ReLU.
    Conv {
        k: usize,
        stride: usize,
        pad: usize,
        cout: usize,
    },
    MaxPool {
        k: usize,
        stride: usize,
    },
    /// The current activation is one of the five LPIPS features.
    Tap,
}

const fn conv(k: usize, stride: usize, pad: usize, cout: usize) -> Op {
    Op::Conv {
        k,
        stride,
        pad,
        cout,
    }
}
const fn c3(cout: usize) -> Op {
    conv(3, 1, 1, cout)
}

const ALEX: &[Op] = &[
    conv(11, 4, 2, 64),
    Op::Tap,
    Op::MaxPool { k: 3, stride: 2 },
    conv(5, 1, 2, 192),
    Op::Tap,
    Op::MaxPool { k: 3, stride: 2 },
    c3(384),
    Op::Tap,
    c3(256),
    Op::Tap,
    c3(256),
    Op::Tap,
];

const POOL2: Op = Op::MaxPool { k: 2, stride: 2 };
const VGG: &[Op] = &[
    c3(64),
    c3(64),
    Op::Tap,
    POOL2,
    c3(128),
    c3(128),
    Op::Tap,
    POOL2,
    c3(256),
    c3(256),
    c3(256),
    Op::Tap,
    POOL2,
    c3(512),
    c3(512),
    c3(512),
    Op::Tap,
    POOL2,
    c3(512),
    c3(512),
    c3(512),
    Op::Tap,
];

/// LPIPS' ScalingLayer: `(x − shift) / scale` per RGB channel, on inputs in [−1,1].
pub(crate) const SHIFT: [f32; 3] = [-0.030, -0.088, -0.188];
pub(crate) const SCALE: [f32; 3] = [0.458, 0.448, 0.450];

impl Net {
    pub fn name(self) -> &'static str {
        match self {
            Net::Alex => "alex",
            Net::Vgg => "vgg",
        }
    }

    /// The weights file name inside the weights folder.
    pub fn file_name(self) -> &'static str {
        match self {
            Net::Alex => "alex.safetensors",
            Net::Vgg => "vgg.safetensors",
        }
    }

    pub(crate) fn ops(self) -> &'static [Op] {
        match self {
            Net::Alex => ALEX,
            Net::Vgg => VGG,
        }
    }

    /// `(kernel side, cin, cout)` of every convolution, in order.
    pub(crate) fn conv_shapes(self) -> Vec<(usize, usize, usize)> {
        let mut cin = 3;
        let mut shapes = Vec::new();
        for op in self.ops() {
            if let Op::Conv { k, cout, .. } = *op {
                shapes.push((k, cin, cout));
                cin = cout;
            }
        }
        shapes
    }

    /// Channel count at each of the five taps (the linear layers' widths).
    pub(crate) fn tap_channels(self) -> Vec<usize> {
        let mut c = 3;
        let mut taps = Vec::new();
        for op in self.ops() {
            match *op {
                Op::Conv { cout, .. } => c = cout,
                Op::Tap => taps.push(c),
                Op::MaxPool { .. } => {}
            }
        }
        taps
    }

    /// Whether every window fits an `h×w` input: the smallest images LPIPS is defined on.
    pub(crate) fn fits(self, h: usize, w: usize) -> bool {
        use super::tensor::out_len;
        let (mut h, mut w) = (h, w);
        for op in self.ops() {
            let (k, stride, pad) = match *op {
                Op::Conv { k, stride, pad, .. } => (k, stride, pad),
                Op::MaxPool { k, stride } => (k, stride, 0),
                Op::Tap => continue,
            };
            match (out_len(h, k, stride, pad), out_len(w, k, stride, pad)) {
                (Some(a), Some(b)) if a > 0 && b > 0 => (h, w) = (a, b),
                _ => return false,
            }
        }
        true
    }

    /// The smallest square side [`Net::fits`] accepts, for error messages.
    pub(crate) fn min_side(self) -> usize {
        (1..4096).find(|&s| self.fits(s, s)).unwrap_or(4096)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tables_describe_the_published_backbones() {
        assert_eq!(Net::Alex.tap_channels(), [64, 192, 384, 256, 256]);
        assert_eq!(Net::Vgg.tap_channels(), [64, 128, 256, 512, 512]);
        assert_eq!(Net::Alex.conv_shapes().len(), 5);
        assert_eq!(Net::Vgg.conv_shapes().len(), 13);
        assert_eq!(Net::Alex.conv_shapes()[1], (5, 64, 192));
    }

    #[test]
    fn alexnet_needs_31_pixels() {
        assert_eq!(Net::Alex.min_side(), 31);
        assert!(!Net::Alex.fits(30, 400));
        assert_eq!(Net::Vgg.min_side(), 16);
    }
}
