//! How F stores its forward feature maps: the pre-activations and normalised outputs of its two
//! wide layers, which its backward reads again. Half precision where the adapter has WGSL `f16`
//! (`SHADER_F16`) halves their memory and the bytes the convolutions gather; every product is
//! accumulated in f32, and the gradients' maps stay f32 (a loss gradient spread over every
//! pixel falls below f16's normal range).

use crate::core::GpuContext;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MapPrecision {
    F32,
    F16,
}

impl MapPrecision {
    /// F16 where the device was created with `SHADER_F16` (off with `COCOG_NO_F16`).
    pub fn for_device(ctx: &GpuContext) -> Self {
        if ctx.shader_f16 {
            MapPrecision::F16
        } else {
            MapPrecision::F32
        }
    }

    /// Bytes per stored value.
    pub fn bytes(self) -> u64 {
        match self {
            MapPrecision::F32 => 4,
            MapPrecision::F16 => 2,
        }
    }

    /// WGSL declaring `map_t`, the element type of the stored maps; kernels read them through
    /// `f32(…)` and write them through `to_map(…)`, which saturates at f16's largest finite
    /// value (a value past it would convert to an indeterminate one, and an infinity would
    /// turn the norm's statistics into NaN).
    pub fn prelude(self) -> &'static str {
        match self {
            MapPrecision::F32 => "alias map_t = f32;\nfn to_map(v: f32) -> map_t { return v; }\n",
            MapPrecision::F16 => {
                "enable f16;\nalias map_t = f16;\n\
                 fn to_map(v: f32) -> map_t { return map_t(clamp(v, -65504.0, 65504.0)); }\n"
            }
        }
    }
}
