//! The two variants of h_θ, where each head's outputs sit, and where each layer's weights sit
//! in the one flat parameter buffer that a single Adam steps.

use cocog_formats::rng::SplitMix64;

/// Positional-encoding frequencies of the Gaussian mean and of the camera centre (the released
/// code's `res_pos = 3`, `res_view = 10`; NeRF's embedder without π, input included).
pub const MEAN_FREQS: usize = 3;
pub const CAMERA_FREQS: usize = 10;
/// γ(μ)'s width (21) and γ(x_cam)'s (63).
pub const MEAN_DIM: usize = 3 * (1 + 2 * MEAN_FREQS);
pub const CAMERA_DIM: usize = 3 * (1 + 2 * CAMERA_FREQS);
/// γ(μ) 21 + γ(x_cam) 63 + exp(log-scale) 3 + normalised quaternion 4: the columns of the
/// first layer's weights.
pub const INPUT_DIM: usize = MEAN_DIM + CAMERA_DIM + 3 + 4;
/// What differs between the Gaussians of a step: γ(μ), scale and rotation. γ(x_cam) is one
/// vector per step, so the GPU adds its product with the first layer's camera columns to
/// that layer's bias once, instead of multiplying it in every Gaussian's row (69 % of the
/// first layer's work).
pub const ROW_DIM: usize = INPUT_DIM - CAMERA_DIM;

/// Which of the two published descriptions h_θ follows (method.md §1).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CocVariant {
    /// The released code: an unbounded position head gated by |1/d − 1/d_F|; M = 4.
    Code,
    /// The paper: aperture K, scaling β ∈ (0,1) and unit directions per copy, offsets of at
    /// most the CoC radius K·|1/d − 1/d_F|/2; M = 5.
    Paper,
    /// A thin lens per photo: the paper's β and directions inside a circle of confusion whose
    /// radius follows from a learned aperture and focus distance of that photo alone
    /// (A/2·|1 − d/d_F|, DoF-NeRF's model), so the MLP shapes the blur but cannot size it.
    Lens,
}

impl CocVariant {
    pub fn name(self) -> &'static str {
        match self {
            Self::Code => "code",
            Self::Paper => "paper",
            Self::Lens => "lens",
        }
    }

    /// The copy count each source uses.
    pub fn default_copies(self) -> u32 {
        match self {
            Self::Code => 4,
            Self::Paper | Self::Lens => 5,
        }
    }

    /// The variant named on the command line.
    pub fn parse(name: &str) -> Option<Self> {
        match name {
            "code" => Some(Self::Code),
            "paper" => Some(Self::Paper),
            "lens" => Some(Self::Lens),
            _ => None,
        }
    }
}

/// Shape of h_θ and of the expansion.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CocConfig {
    pub variant: CocVariant,
    /// CoC copies M (the base set comes on top).
    pub copies: u32,
    /// Hidden width of the 3-layer ReLU trunk.
    pub width: u32,
    /// Subtract the copies' mean offset, so they sit around the base as a circle of
    /// confusion sits around the in-focus point (neither source does; without it the copies
    /// can translate a Gaussian per view).
    pub centred: bool,
    /// Modulate the base set's scale and rotation too, as the released code does; the test
    /// views render the base unmodulated, so without it training renders what testing does.
    pub modulate_base: bool,
}

impl CocConfig {
    pub fn new(variant: CocVariant) -> Self {
        Self {
            variant,
            copies: variant.default_copies(),
            width: 64,
            centred: false,
            modulate_base: true,
        }
    }

    pub fn heads(&self) -> HeadLayout {
        HeadLayout::new(self.variant, self.copies as usize)
    }

    pub fn mlp(&self) -> MlpLayout {
        MlpLayout::new(self.width as usize, self.heads().len)
    }
}

/// Offsets of each head's outputs in h_θ's output vector. Per-copy vectors are copy-major
/// (`pos + 3·m + k`); the scale and rotation heads cover the M copies and the base set.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct HeadLayout {
    pub copies: usize,
    /// Paper: softplus → aperture K (one value).
    pub aperture: Option<usize>,
    /// Paper and lens: sigmoid → β per copy.
    pub beta: Option<usize>,
    /// Code: offsets per copy; paper and lens: directions, normalised.
    pub pos: usize,
    /// 3 per set (M + 1 sets), through the gated log-clamp to [1, 1.1].
    pub scale: usize,
    /// 4 per set, likewise.
    pub rot: usize,
    pub len: usize,
}

impl HeadLayout {
    pub fn new(variant: CocVariant, m: usize) -> Self {
        let (aperture, beta, pos) = match variant {
            CocVariant::Code => (None, None, 0),
            CocVariant::Paper => (Some(0), Some(1), 1 + m),
            CocVariant::Lens => (None, Some(0), m),
        };
        let scale = pos + 3 * m;
        let rot = scale + 3 * (m + 1);
        Self {
            copies: m,
            aperture,
            beta,
            pos,
            scale,
            rot,
            len: rot + 4 * (m + 1),
        }
    }
}

/// Where each layer's weights (`[out][in]`, row-major) and biases sit in the flat buffer.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MlpLayout {
    pub width: usize,
    pub outputs: usize,
    /// Per layer (3 trunk layers, then the heads): (fan in, fan out, weight offset, bias offset).
    pub layers: [(usize, usize, usize, usize); 4],
    pub len: usize,
}

impl MlpLayout {
    pub fn new(width: usize, outputs: usize) -> Self {
        let dims = [
            (INPUT_DIM, width),
            (width, width),
            (width, width),
            (width, outputs),
        ];
        let mut at = 0;
        let layers = dims.map(|(fan_in, fan_out)| {
            let w = at;
            let b = w + fan_in * fan_out;
            at = b + fan_out;
            (fan_in, fan_out, w, b)
        });
        Self {
            width,
            outputs,
            layers,
            len: at,
        }
    }
}

/// PyTorch's `nn.Linear` default, which the released code keeps: weights and biases uniform in
/// ±1/√fan_in. Deterministic in `seed`.
pub fn init_weights(layout: &MlpLayout, seed: u64) -> Vec<f32> {
    let mut rng = SplitMix64::new(seed);
    let mut out = vec![0.0f32; layout.len];
    for &(fan_in, fan_out, w, b) in &layout.layers {
        let bound = 1.0 / (fan_in as f64).sqrt();
        for v in &mut out[w..b + fan_out] {
            *v = (bound * (2.0 * rng.next_f64() - 1.0)) as f32;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_input_is_the_released_codes_91() {
        assert_eq!(INPUT_DIM, 91);
        assert_eq!((MEAN_DIM, CAMERA_DIM, ROW_DIM), (21, 63, 28));
    }

    #[test]
    fn heads_match_the_variants() {
        // Code, M = 4: scale 15 + rotation 20 + position 12.
        assert_eq!(HeadLayout::new(CocVariant::Code, 4).len, 47);
        // Paper, M = 5: K 1 + β 5 + directions 15 + scale 18 + rotation 24.
        let p = HeadLayout::new(CocVariant::Paper, 5);
        assert_eq!((p.pos, p.scale, p.rot, p.len), (6, 21, 39, 63));
    }

    #[test]
    fn layers_tile_the_buffer() {
        let l = MlpLayout::new(64, 47);
        assert_eq!(l.len, 91 * 64 + 64 + 2 * (64 * 64 + 64) + 64 * 47 + 47);
        let w = init_weights(&l, 7);
        let bound = 1.0 / 91f32.sqrt();
        assert!(w[..91 * 64].iter().all(|v| v.abs() <= bound));
        assert!(w.iter().filter(|v| **v == 0.0).count() < 4);
    }
}
