//! An experimental matrix product on cooperative matrices (tensor cores), for measuring what
//! they would give F's convolutions: about 175 GFLOP a step at 400×300, which the f32 tiled
//! product (`Gemm`) runs on the GPU's plain arithmetic. Plain row-major matrices only, A and B
//! in f16, C in f32; sizes in whole 64×64 blocks and 32-deep slices. Nothing in a training step
//! uses it yet. Exists only where `GpuContext::cooperative_f16` (opt-in: wgpu marks the feature
//! experimental).

use crate::core::{Bind, GpuContext, Kernel, Recorder, shader};

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Dims {
    m: u32,
    n: u32,
    k: u32,
    pad: u32,
}

#[derive(Debug)]
pub struct CoopGemm {
    kernel: Kernel,
}

impl CoopGemm {
    /// The kernel, or `None` where the context did not enable 16×16×16 f16→f32 cooperative
    /// matrices with 32-wide subgroups.
    pub fn new(ctx: &GpuContext) -> Option<Self> {
        if !ctx.cooperative_f16 {
            return None;
        }
        let module = shader(ctx, "coop gemm", &Self::wgsl());
        Some(Self {
            kernel: Kernel::labelled(ctx, &module, "coop_gemm", "coop gemm"),
        })
    }

    /// The kernel's WGSL, enables included (its tests compile it without a device).
    pub fn wgsl() -> String {
        format!(
            "enable f16;\nenable wgpu_cooperative_matrix;\n{}",
            include_str!("coop_gemm.wgsl")
        )
    }

    /// Whether an M×N×K product fits the kernel's blocks.
    pub fn fits(m: u32, n: u32, k: u32) -> bool {
        m > 0
            && n > 0
            && k > 0
            && m.is_multiple_of(64)
            && n.is_multiple_of(64)
            && k.is_multiple_of(32)
    }

    /// Records C = A·B: `a` is M×K and `b` K×N of f16, `c` M×N of f32, all row-major.
    pub fn encode(
        &self,
        rec: &mut Recorder,
        (m, n, k): (u32, u32, u32),
        a: &dyn Bind,
        b: &dyn Bind,
        c: &dyn Bind,
    ) {
        assert!(
            Self::fits(m, n, k),
            "coop gemm: {m}×{n}×{k} is not in 64×64×32 blocks"
        );
        let dims = rec.uniform(&Dims { m, n, k, pad: 0 });
        self.kernel.dispatch(
            rec,
            &[(0, &dims), (1, a), (2, b), (3, c)],
            [n / 64, m / 64, 1],
        );
    }
}
