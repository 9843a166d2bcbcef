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

    /// Bytes of one of F's feature maps over `images` renders of `pixels` pixels (channels
    /// floats per pixel and render): its largest buffer, which must fit one binding.
    pub fn map_bytes(&self, pixels: u64, images: u32) -> u64 {
        4 * pixels * u64::from(images) * u64::from(self.channels)
    }

    /// Renders F runs at once when one binding holds at most `binding_limit` bytes: all
    /// `images`, or as many as a binding holds of a layer's maps (at least one).
    pub fn renders_per_chunk(&self, binding_limit: u64, pixels: u64, images: u32) -> u32 {
        let per_image = self.map_bytes(pixels, 1).max(1);
        u32::try_from(binding_limit / per_image)
            .unwrap_or(u32::MAX)
            .clamp(1, images.max(1))
    }

    /// What running in chunks adds: the backward recomputes each chunk's two normalised
    /// layers (their convolutions' forward operations), since only the last chunk's maps are
    /// kept.
    pub fn recompute_flops(&self, pixels: u64, images: u32) -> f64 {
        let c = f64::from(self.channels);
        2.0 * pixels as f64 * f64::from(images) * (25.0 * 3.0 * c + 9.0 * c * c)
    }

    /// Floating-point operations (a multiply-add counts 2) of F's convolutions over `images`
    /// renders of `pixels` pixels: (forward, backward). The backward takes every layer's weight
    /// gradient and the input gradients of the second layer and the head; F sees detached
    /// renders, so the first layer has no input gradient. Norms, ReLUs and the softmax blend
    /// are a few operations per value and are left out.
    pub fn flops(&self, pixels: u64, images: u32) -> (f64, f64) {
        let c = f64::from(self.channels);
        let (first, second, head) = (25.0 * 3.0 * c, 9.0 * c * c, 9.0 * c);
        let per_value = 2.0 * pixels as f64 * f64::from(images);
        (
            per_value * (first + second + head),
            per_value * (first + 2.0 * second + 2.0 * head),
        )
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
    fn flops_count_every_multiply_add_of_the_convolutions() {
        // One pixel of one render at 2 channels: conv1 150, conv2 36, head 18 multiply-adds.
        let (f, b) = CompositorConfig::with_channels(2).flops(1, 1);
        assert_eq!((f, b), (2.0 * 204.0, 2.0 * (150.0 + 72.0 + 36.0)));
        // The paper's F over six 100×75 renders: 3.8 GFLOP forward.
        let (f, _) = CompositorConfig::default().flops(7500, 6);
        assert!((f - 3.80e9).abs() < 0.01e9, "{f}");
        // A recompute is the forward less the head (18 of 204 multiply-adds at 2 channels).
        let c2 = CompositorConfig::with_channels(2);
        assert_eq!(c2.recompute_flops(1, 1), 2.0 * (150.0 + 36.0));
    }

    #[test]
    fn chunks_hold_what_one_binding_holds() {
        let c = CompositorConfig::with_channels(4);
        let one = c.map_bytes(100, 1);
        assert_eq!(c.renders_per_chunk(u64::MAX, 100, 6), 6);
        assert_eq!(c.renders_per_chunk(2 * one + 1, 100, 6), 2);
        assert_eq!(c.renders_per_chunk(one - 1, 100, 6), 1);
    }

    #[test]
    fn the_layers_tile_the_buffer() {
        let l = CompositorLayout::new(64);
        assert_eq!(l.len, 64 * 75 + 64 + 64 * 64 * 9 + 64 + 64 * 9);
        let p = l.init(3);
        assert!(p[l.conv2_w..l.head_w].iter().all(|v| v.abs() <= 1.0 / 24.0));
        assert!(p.iter().filter(|v| **v == 0.0).count() < 4);
    }
}
