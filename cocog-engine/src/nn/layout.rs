//! The compositor F's shape (the released code's 3 convolutions) and where each weight sits in
//! the one flat parameter buffer that a single Adam steps.

use cocog_formats::rng::SplitMix64;

/// InstanceNorm2d's default ε.
pub const IN_EPS: f64 = 1e-5;

/// F's width; the layers are fixed: 5×5 3→C, 3×3 C→C (each + bias, ReLU, InstanceNorm), and a
/// bias-free 3×3 C→1 head giving one logit per pixel and render.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CompositorConfig {
    pub channels: u32,
}

impl CompositorConfig {
    pub fn with_channels(channels: u32) -> Self {
        Self {
            channels: channels.max(1),
        }
    }

    pub fn layout(&self) -> CompositorLayout {
        CompositorLayout::new(self.channels as usize)
    }
}

impl Default for CompositorConfig {
    fn default() -> Self {
        Self::with_channels(64)
    }
}

/// Offsets of each layer's weights (`[out][in][ky][kx]`) and biases.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CompositorLayout {
    pub channels: usize,
    pub conv1_w: usize,
    pub conv1_b: usize,
    pub conv2_w: usize,
    pub conv2_b: usize,
    pub head_w: usize,
    pub len: usize,
}

impl CompositorLayout {
    pub fn new(c: usize) -> Self {
        let conv1_w = 0;
        let conv1_b = conv1_w + c * 3 * 25;
        let conv2_w = conv1_b + c;
        let conv2_b = conv2_w + c * c * 9;
        let head_w = conv2_b + c;
        Self {
            channels: c,
            conv1_w,
            conv1_b,
            conv2_w,
            conv2_b,
            head_w,
            len: head_w + c * 9,
        }
    }

    /// PyTorch's `nn.Conv2d` default, which the released code keeps: weights and biases
    /// uniform in ±1/√(fan in). Deterministic in `seed`.
    pub fn init(&self, seed: u64) -> Vec<f32> {
        let c = self.channels;
        let mut rng = SplitMix64::new(seed);
        let mut out = vec![0.0f32; self.len];
        let spans = [
            (self.conv1_w, self.conv2_w, 3 * 25),
            (self.conv2_w, self.head_w, c * 9),
            (self.head_w, self.len, c * 9),
        ];
        for (from, to, fan_in) in spans {
            let bound = 1.0 / (fan_in as f64).sqrt();
            for v in &mut out[from..to] {
                *v = (bound * (2.0 * rng.next_f64() - 1.0)) as f32;
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_layers_tile_the_buffer() {
        let l = CompositorLayout::new(64);
        assert_eq!(l.len, 64 * 75 + 64 + 64 * 64 * 9 + 64 + 64 * 9);
        let p = l.init(3);
        assert!(p[l.conv2_w..l.head_w].iter().all(|v| v.abs() <= 1.0 / 24.0));
        assert!(p.iter().filter(|v| **v == 0.0).count() < 4);
    }
}
