//! Training on photos whose per-pixel buffers outgrow one buffer binding (lavapipe binds
//! 128 MiB: 8.4 Mpixel of rgba f32). A step renders, scores and differentiates the frame band
//! by band, and adds up the bands' parameter gradients and densification statistics into what
//! one pass over the frame would give (the step counts as overflowed when any band did):
//! - a band is whole tile rows, so it renders exactly the frame's pixels (`ImageSpec::rows`);
//! - it renders one tile row beyond the rows it scores on each side, the 10 rows the SSIM
//!   gradient of a scored row reads, and only its scored rows get a gradient, so the bands'
//!   losses and gradients add up to the frame's;
//! - the targets stay whole frames on the GPU; a band binds its rows of one.
//!
//! A banded step submits once per band (each band re-aims the batch's camera), then once more.

use std::num::NonZeroU64;

use cocog_engine::{
    AddInto, Batch, Bind, GpuBuffer, GpuContext, Kernel, LossRows, Recorder, TILE_SIZE,
    sh_coeffs_per_channel, shader,
};

use super::{Plan, Stopwatch, Trainer};
use crate::TrainError;

/// Bytes of one rgba f32 pixel: the render, the target and the loss gradient.
const RGBA_BYTES: u64 = 16;

/// Rows `scored` of a frame, rendered as rows `rendered` (the scored ones and their halo).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct FrameBand {
    pub scored: (u32, u32),
    pub rendered: (u32, u32),
}

/// The bands of a `w`×`h` frame under a binding of `limit` bytes: `None` when the frame fits
/// one binding, `Err` naming the sizes when not even one tile row between its halos does.
pub(super) fn plan(w: u32, h: u32, limit: u64) -> Result<Option<Vec<FrameBand>>, String> {
    let row_bytes = RGBA_BYTES * u64::from(w);
    if row_bytes * u64::from(h) <= limit {
        return Ok(None);
    }
    let tile_rows = limit / (row_bytes * u64::from(TILE_SIZE));
    let scored_tiles = tile_rows.saturating_sub(2);
    if scored_tiles == 0 {
        return Err(format!(
            "{w}-pixel-wide photos are trained in bands of rows, and a band of 3 tile rows \
             ({} rows) needs {}, more than the {} this adapter binds: train on smaller images \
             (--downscale)",
            3 * TILE_SIZE,
            mib(3 * row_bytes * u64::from(TILE_SIZE)),
            mib(limit)
        ));
    }
    let scored = u32::try_from(scored_tiles * u64::from(TILE_SIZE)).unwrap_or(u32::MAX);
    Ok(Some(
        (0..h.div_ceil(scored))
            .map(|b| {
                let top = b * scored;
                let bottom = (top + scored).min(h);
                FrameBand {
                    scored: (top, bottom),
                    rendered: (top.saturating_sub(TILE_SIZE), (bottom + TILE_SIZE).min(h)),
                }
            })
            .collect(),
    ))
}

/// `Err` naming the sizes when a `w`×`h` target photo (kept whole on the GPU, its bands bound
/// from it) exceeds the largest buffer the adapter creates, `max_buffer` bytes.
pub(super) fn check_targets(w: u32, h: u32, max_buffer: u64) -> Result<(), String> {
    let bytes = RGBA_BYTES * u64::from(w) * u64::from(h);
    if bytes <= max_buffer {
        return Ok(());
    }
    Err(format!(
        "{w}×{h} photos are kept on the GPU as {} buffers, and this adapter's largest buffer \
         is {}: train on smaller images (--downscale {} or more)",
        mib(bytes),
        mib(max_buffer),
        (bytes as f64 / max_buffer as f64).sqrt().ceil()
    ))
}

fn mib(bytes: u64) -> String {
    format!("{:.1} MiB", bytes as f64 / f64::from(1 << 20))
}

/// The kernels that gather a frame's bands.
#[derive(Debug)]
pub(super) struct BandKernels {
    add: AddInto,
    merge_pass: Kernel,
    merge_status: Kernel,
}

impl BandKernels {
    pub fn new(ctx: &GpuContext) -> Self {
        let module = shader(ctx, "frame bands", include_str!("bands.wgsl"));
        Self {
            add: AddInto::new(ctx),
            merge_pass: Kernel::new(ctx, &module, "merge_pass"),
            merge_status: Kernel::new(ctx, &module, "merge_status"),
        }
    }
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Sizes {
    count: u32,
    pad: [u32; 3],
}

impl<'c> Trainer<'c> {
    /// `optimise` for a frame that needs `bands`; `batch` is aimed at the whole frame.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn optimise_banded(
        &mut self,
        rec: &mut Recorder<'c>,
        batch: &mut Batch,
        view: usize,
        it: u32,
        plan: Plan,
        bands: &[FrameBand],
        watch: &mut Stopwatch,
    ) -> Result<(), TrainError> {
        let ctx = self.ctx;
        let frame = batch.images[0];
        let (w, h) = (frame.camera.width, frame.camera.height);
        let n = batch.params.num_gaussians;
        let lambda = self.config.lambda_dssim;
        let frame_pixels = u64::from(w) * u64::from(h);
        let rows_of = |b: &FrameBand| LossRows {
            out: (b.scored.0 - b.rendered.0, b.scored.1 - b.rendered.0),
            frame_pixels,
        };
        let slots = bands
            .iter()
            .map(|b| {
                let rendered = b.rendered.1 - b.rendered.0;
                self.loss.slots(ctx, w, rendered, 1, rows_of(b))
            })
            .sum::<Result<u32, _>>()?;
        let coeffs = 3 * sh_coeffs_per_channel(batch.params.sh_degree) as u32;
        let floats = [3 * n, 3 * n, 4 * n, n, coeffs * n];
        const NAMES: [&str; 5] = [
            "frame v_means",
            "frame v_log_scales",
            "frame v_quats",
            "frame v_opacity_logits",
            "frame v_sh",
        ];
        let mut band_rec = ctx.recorder();
        let ws = &mut self.ws;
        let sums: Vec<GpuBuffer> = NAMES
            .iter()
            .zip(floats)
            .map(|(name, f)| ws.zeroed(&mut band_rec, name, u64::from(f) * 4))
            .collect();
        let frame_projected = ws.zeroed(&mut band_rec, "frame projected", u64::from(n) * 48);
        let frame_v_projected = ws.zeroed(&mut band_rec, "frame v_projected", u64::from(n) * 40);
        let frame_status = ws.zeroed(&mut band_rec, "frame status", 8);
        let partials = ws.buffer(ctx, "frame loss partials", u64::from(slots.max(1)) * 16);
        let mut slot = 0u64;
        let mut last_out = None;
        for band in bands {
            let rendered = band.rendered.1 - band.rendered.0;
            batch.set_images(ctx, vec![frame.rows(band.rendered.0, rendered)])?;
            let ws = &mut self.ws;
            let state = self
                .renderer
                .encode_forward(&mut band_rec, ws, batch, self.capacity);
            let target = wgpu::BufferBinding {
                buffer: &self.targets[view].buffer,
                offset: u64::from(band.rendered.0) * u64::from(w) * RGBA_BYTES,
                size: NonZeroU64::new(u64::from(rendered) * u64::from(w) * RGBA_BYTES),
            };
            let out = self.loss.compute_rows(
                &mut band_rec,
                ws,
                &state.rgba,
                &target,
                w,
                rendered,
                1,
                rows_of(band),
                lambda,
            )?;
            let bytes = out.partials_bytes();
            band_rec.encoder().copy_buffer_to_buffer(
                &out.partials.buffer,
                0,
                &partials.buffer,
                slot * 16,
                bytes,
            );
            slot += bytes / 16;
            watch.times.forward += watch.lap_recorded(&mut band_rec)?;
            let grads =
                self.renderer
                    .encode_backward(&mut band_rec, ws, batch, &state, &out.v_pred, None);
            let g = &grads.params;
            let parts = [&g.means, &g.log_scales, &g.quats, &g.opacity_logits, &g.sh];
            let k = &self.bands_kernels;
            for ((sum, part), f) in sums.iter().zip(parts).zip(floats) {
                k.add.encode(&mut band_rec, part, sum, f);
            }
            if plan.gather_stats {
                let u = band_rec.uniform(&Sizes {
                    count: n,
                    pad: [0; 3],
                });
                let binds: [(u32, &dyn Bind); 5] = [
                    (0, &u),
                    (3, &state.projected),
                    (4, &grads.v_projected),
                    (5, &frame_projected),
                    (6, &frame_v_projected),
                ];
                k.merge_pass
                    .dispatch_1d(&mut band_rec, &binds, n.div_ceil(256));
            }
            k.merge_status.dispatch(
                &mut band_rec,
                &[(7, &state.status), (8, &frame_status)],
                [1, 1, 1],
            );
            watch.times.backward += watch.lap_recorded(&mut band_rec)?;
            std::mem::replace(&mut band_rec, ctx.recorder()).submit();
            last_out = Some(out);
        }
        let out = last_out
            .ok_or_else(|| TrainError::Invalid("a frame without bands".into()))?
            .with_partials(partials, slot as usize);
        if plan.gather_stats {
            let pass: (&dyn Bind, &dyn Bind, &dyn Bind) =
                (&frame_projected, &frame_v_projected, &frame_status);
            self.stats.accumulate_from(rec, pass, w, h, 1);
        }
        watch.times.density += watch.lap_recorded(rec)?;
        self.record_readings(rec, &frame_status, &out, view, it, &batch.params)?;
        if plan.densify {
            return Ok(());
        }
        let v = [0, 1, 2, 3, 4].map(|i| &sums[i].buffer);
        self.step_base(rec, &batch.params, v, it, plan, &frame_status);
        watch.times.optimizer += watch.lap_recorded(rec)?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_frame_that_fits_has_no_bands() {
        assert_eq!(plan(100, 75, 16 * 7500), Ok(None));
    }

    #[test]
    fn bands_are_tile_rows_with_a_tile_row_of_halo_inside_the_frame() {
        // 6 tile rows a band: 4 scored.
        let limit = 16 * 10 * 16 * 6;
        let bands = plan(10, 150, limit).unwrap().unwrap();
        let scored: Vec<(u32, u32)> = bands.iter().map(|b| b.scored).collect();
        assert_eq!(scored, [(0, 64), (64, 128), (128, 150)]);
        let rendered: Vec<(u32, u32)> = bands.iter().map(|b| b.rendered).collect();
        assert_eq!(rendered, [(0, 80), (48, 144), (112, 150)]);
        for b in &bands {
            let rows = u64::from(b.rendered.1 - b.rendered.0);
            assert!(16 * 10 * rows <= limit);
            assert_eq!(b.rendered.0 % TILE_SIZE, 0);
        }
    }

    #[test]
    fn a_target_past_the_largest_buffer_is_refused_by_size() {
        assert!(check_targets(4000, 3000, 192_000_000).is_ok());
        let e = check_targets(4000, 3000, 191_999_999).unwrap_err();
        assert!(e.contains("4000×3000") && e.contains("183.1 MiB"), "{e}");
        assert!(e.contains("--downscale 2"), "{e}");
    }

    #[test]
    fn a_frame_too_wide_for_three_tile_rows_is_refused_by_size() {
        let e = plan(1000, 1000, 16 * 1000 * 47).unwrap_err();
        assert!(
            e.contains("1000-pixel-wide") && e.contains("--downscale"),
            "{e}"
        );
    }
}
