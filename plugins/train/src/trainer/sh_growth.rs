//! SH growth on the GPU: the SH buffer and its Adam moments re-laid out for a higher degree.

use cocog_engine::{
    AdamMoments, GpuBuffer, GpuContext, Kernel, Recorder, sh_coeffs_per_channel, shader,
};

use super::Trainer;
use crate::TrainError;

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    rows: u32,
    old_k: u32,
    new_k: u32,
    pad: u32,
}

/// The kernel `raise_sh_degree` (and `record_widen_sh`) runs.
pub fn widen_kernel(ctx: &GpuContext) -> Kernel {
    let module = shader(ctx, "widen_sh", include_str!("widen_sh.wgsl"));
    Kernel::new(ctx, &module, "widen_sh")
}

/// Records widening every row `buffer` has room for, from `old_k` to `new_k` coefficients
/// per channel, into a new buffer (rows past the live ones are buried or unused, and keep the
/// room densification reserved).
pub fn record_widen_sh(
    rec: &mut Recorder,
    kernel: &Kernel,
    buffer: &GpuBuffer,
    old_k: u32,
    new_k: u32,
) -> GpuBuffer {
    let rows = (buffer.size() / (12 * u64::from(old_k))) as u32;
    let wide = rec
        .ctx()
        .storage("sh", u64::from(rows) * 12 * u64::from(new_k));
    let params = rec.uniform(&Params {
        rows,
        old_k,
        new_k,
        pad: 0,
    });
    kernel.dispatch_1d(
        rec,
        &[(0, &params), (1, buffer), (2, &wide)],
        (rows * 3 * new_k).div_ceil(256),
    );
    wide
}

impl Trainer<'_> {
    /// Re-lays the SH buffer and its Adam moments out for `degree`, new coefficients zero, in
    /// one submission of its own and without a read-back. INRIA allocates degree 3 up front
    /// and masks; the result is the same because masked coefficients get zero gradients, so
    /// their parameters and moments stay zero until used.
    pub(super) fn raise_sh_degree(&mut self, degree: u32) -> Result<(), TrainError> {
        let ctx = self.ctx;
        let params = self
            .batch
            .as_mut()
            .map(|b| &mut b.params)
            .ok_or(TrainError::Poisoned)?;
        let n = params.num_gaussians;
        let (old_k, new_k) = (
            sh_coeffs_per_channel(params.sh_degree) as u32,
            sh_coeffs_per_channel(degree) as u32,
        );
        let mut rec = ctx.recorder();
        let k = &self.widen_sh;
        params.sh = record_widen_sh(&mut rec, k, &params.sh, old_k, new_k);
        params.sh_degree = degree;
        let m = &self.moments.sh;
        self.moments.sh = AdamMoments {
            m: record_widen_sh(&mut rec, k, &m.m, old_k, new_k),
            v: record_widen_sh(&mut rec, k, &m.v, old_k, new_k),
            len: n * 3 * new_k,
        };
        rec.submit();
        Ok(())
    }
}

/// Copies per-channel SH blocks of `old_k` coefficients into blocks of `new_k`, zero-filled:
/// the CPU model of `record_widen_sh`.
pub fn widen_sh(old: &[f32], old_k: usize, new_k: usize) -> Vec<f32> {
    let mut out = vec![0.0; old.len() / old_k * new_k];
    for (src, dst) in old.chunks_exact(old_k).zip(out.chunks_exact_mut(new_k)) {
        dst[..old_k].copy_from_slice(src);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::widen_sh;

    #[test]
    fn widening_keeps_each_channel_block_in_place() {
        // Two Gaussians × 3 channels at degree 0 (1 coefficient) → degree 1 (4).
        let old = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0];
        let new = widen_sh(&old, 1, 4);
        assert_eq!(new.len(), 24);
        for (i, v) in old.iter().enumerate() {
            assert_eq!(new[4 * i], *v);
            assert_eq!(&new[4 * i + 1..4 * i + 4], &[0.0; 3]);
        }
        let again = widen_sh(&new, 4, 9);
        assert_eq!(again[9 * 5], 6.0);
        assert_eq!(again.len(), 54);
    }
}
