//! The GPU loss and its gradient against the f64 reference (FD-checked in
//! reference_loss_fd.rs), and its PSNR partial sums against a plain f64 PSNR, on a batch of
//! two odd-sized images with predictions outside [0, 1] (which the PSNR clamps); in one pass,
//! and in bands of rows as images too large for one buffer binding are done (a binding limit
//! lowered to force 5-row and 1-row bands, halos and image edges inside bands included); on
//! dark, nearly flat images, where SSIM's constants dominate; and a frame scored band by band,
//! as the trainer trains photos larger than a binding.

mod common;

use cocog_engine::reference::loss::image_loss;
use cocog_engine::{ImageLoss, Workspace};
use common::{Rng, gpu};

#[test]
fn gpu_loss_matches_reference() {
    let Some(ctx) = gpu() else { return };
    let (w, h, images) = (23usize, 17usize, 2usize);
    let mut rng = Rng::new(12);
    let npix = w * h * images;
    let pred: Vec<[f32; 4]> = (0..npix)
        .map(|_| std::array::from_fn(|_| rng.range_f32(-0.1, 1.1)))
        .collect();
    // A target correlated with the prediction, so SSIM is far from zero.
    let target: Vec<[f32; 4]> = pred
        .iter()
        .map(|p| std::array::from_fn(|k| (p[k] * 0.7 + rng.range_f32(0.0, 0.3)).min(1.0)))
        .collect();
    compare_with_reference(ctx, &pred, &target, (w, h, images));
}

/// Dark, nearly flat images, where SSIM's constants C1 and C2 outweigh the means and variances
/// they stabilise: a wrong constant would pass the test above but not this one.
#[test]
fn gpu_loss_of_dark_flat_images_matches_reference() {
    let Some(ctx) = gpu() else { return };
    // Two tiles across exactly, and fewer rows than the 11-row window.
    let (w, h, images) = (32usize, 9usize, 1usize);
    let mut rng = Rng::new(14);
    let pred: Vec<[f32; 4]> = (0..w * h)
        .map(|_| std::array::from_fn(|_| 0.01 + rng.range_f32(0.0, 0.004)))
        .collect();
    let target: Vec<[f32; 4]> = (0..w * h)
        .map(|_| std::array::from_fn(|_| 0.012 + rng.range_f32(0.0, 0.004)))
        .collect();
    compare_with_reference(ctx, &pred, &target, (w, h, images));
}

fn compare_with_reference(
    ctx: &cocog_engine::GpuContext,
    pred: &[[f32; 4]],
    target: &[[f32; 4]],
    (w, h, images): (usize, usize, usize),
) {
    let npix = w * h * images;
    // Bytes of one row of SSIM terms: a limit of 15 rows leaves 5-row bands (and their 5-row
    // halos), 11 rows 1-row.
    let row = ImageLoss::largest_binding(w as u64);
    // One workspace throughout, as in training: the one-pass case after the banded ones finds
    // their partial sums (more slots) in its buffer, and must not read past its own.
    let mut ws = Workspace::default();
    for (limit, lambda) in [
        (None, 0.0f32),
        (None, 0.2),
        (None, 1.0),
        (Some(15 * row), 0.2),
        (Some(15 * row), 1.0),
        (Some(11 * row), 0.2),
        (None, 0.2),
    ] {
        let loss = match limit {
            Some(bytes) => ImageLoss::new(ctx).with_binding_limit(bytes),
            None => ImageLoss::new(ctx),
        };
        let mut rec = ctx.recorder();
        let out = loss
            .compute(
                &mut rec,
                &mut ws,
                &ctx.storage_from("pred", pred),
                &ctx.storage_from("target", target),
                w as u32,
                h as u32,
                images as u32,
                lambda,
            )
            .expect("the loss plans within the limit");
        rec.submit();
        let gpu_loss = out.read_loss(ctx).unwrap();
        let partials: Vec<u8> = ctx
            .read(&out.partials, out.partials_bytes() as usize)
            .unwrap();
        let value = out.value_from(&partials);
        assert!((value.loss - gpu_loss).abs() < 1e-12);
        let sq: f64 = pred
            .iter()
            .zip(target)
            .flat_map(|(p, t)| (0..3).map(move |k| f64::from(p[k].clamp(0.0, 1.0) - t[k])))
            .map(|d| d * d)
            .sum();
        let ref_psnr = 10.0 * (3.0 * npix as f64 / sq).log10();
        assert!(
            (value.psnr - ref_psnr).abs() < 1e-4,
            "λ={lambda} limit {limit:?}: PSNR {} vs {ref_psnr}",
            value.psnr
        );
        let gpu_grad: Vec<[f32; 4]> = ctx.read(&out.v_pred, npix).unwrap();
        let mut ref_loss = 0.0;
        let mut ref_grad = Vec::new();
        for i in 0..images {
            let rgb = |v: &[[f32; 4]]| -> Vec<[f64; 3]> {
                v[i * w * h..(i + 1) * w * h]
                    .iter()
                    .map(|p| [p[0], p[1], p[2]].map(f64::from))
                    .collect()
            };
            let (l, g) = image_loss(&rgb(pred), &rgb(target), w, h, f64::from(lambda));
            ref_loss += l / images as f64;
            ref_grad.extend(g.into_iter().map(|g| g.map(|v| v / images as f64)));
        }
        assert!(
            (gpu_loss - ref_loss).abs() < 1e-5 * ref_loss.abs().max(1e-3),
            "λ={lambda} limit {limit:?}: loss {gpu_loss} vs {ref_loss}"
        );
        let scale = ref_grad
            .iter()
            .flatten()
            .fold(0.0f64, |m, v| m.max(v.abs()));
        for (p, (g, r)) in gpu_grad.iter().zip(&ref_grad).enumerate() {
            for k in 0..3 {
                // Per scalar: f32 rounding of each value, and of the sums it cancels from.
                let err = (f64::from(g[k]) - r[k]).abs();
                assert!(
                    err < 1e-4 * r[k].abs() + 1e-6 * scale,
                    "λ={lambda} limit {limit:?} pixel {p} channel {k}: {} vs {}",
                    g[k],
                    r[k]
                );
            }
            assert_eq!(g[3], 0.0, "alpha gradient must stay zero");
        }
    }
}

/// A frame scored band by band (`compute_rows`), as the trainer does for photos larger than one
/// binding: each band holds its scored rows and up to 10 rows beyond them on each side (what
/// the SSIM gradient of a scored row reads), its sums are parts of the frame's loss, and its
/// gradient is the frame's on its scored rows and zero elsewhere. Also with the loss's own
/// bands inside a band (a binding of 12 rows of SSIM terms: 2-row bands).
#[test]
fn gpu_loss_of_a_frame_in_row_bands_adds_up_to_the_frame() {
    use cocog_engine::LossRows;
    let Some(ctx) = gpu() else { return };
    let (w, h) = (23usize, 40usize);
    let mut rng = Rng::new(13);
    let pred: Vec<[f32; 4]> = (0..w * h)
        .map(|_| std::array::from_fn(|_| rng.range_f32(-0.1, 1.1)))
        .collect();
    let target: Vec<[f32; 4]> = pred
        .iter()
        .map(|p| std::array::from_fn(|k| (p[k] * 0.7 + rng.range_f32(0.0, 0.3)).min(1.0)))
        .collect();
    let lambda = 0.2f32;
    let rgb = |v: &[[f32; 4]]| -> Vec<[f64; 3]> {
        v.iter()
            .map(|p| [p[0], p[1], p[2]].map(f64::from))
            .collect()
    };
    let (ref_loss, ref_grad) = image_loss(&rgb(&pred), &rgb(&target), w, h, f64::from(lambda));
    let scale = ref_grad
        .iter()
        .flatten()
        .fold(0.0f64, |m, v| m.max(v.abs()));
    let row = ImageLoss::largest_binding(w as u64);
    for limit in [None, Some(12 * row)] {
        let loss = match limit {
            Some(bytes) => ImageLoss::new(ctx).with_binding_limit(bytes),
            None => ImageLoss::new(ctx),
        };
        let mut total = 0.0;
        let mut scored_rows = 0;
        // One workspace, as a training step's: the top band, last, reuses the middle band's
        // larger scratch, whose rows hold that band's gradient where the top band has halo.
        let mut ws = Workspace::default();
        for (top, bottom) in [(26usize, 40usize), (13, 26), (0, 13)] {
            let (first, last) = (top.saturating_sub(10), (bottom + 10).min(h));
            let band = |v: &[[f32; 4]]| v[first * w..last * w].to_vec();
            let rows = LossRows {
                out: ((top - first) as u32, (bottom - first) as u32),
                frame_pixels: (w * h) as u64,
            };
            let mut rec = ctx.recorder();
            let out = loss
                .compute_rows(
                    &mut rec,
                    &mut ws,
                    &ctx.storage_from("pred", &band(&pred)),
                    &ctx.storage_from("target", &band(&target)),
                    w as u32,
                    (last - first) as u32,
                    1,
                    rows,
                    lambda,
                )
                .expect("the loss plans within the limit");
            rec.submit();
            assert_eq!(
                loss.slots(ctx, w as u32, (last - first) as u32, 1, rows)
                    .unwrap() as usize,
                out.num_groups
            );
            total += out.read_loss(ctx).unwrap();
            let grad: Vec<[f32; 4]> = ctx.read(&out.v_pred, (last - first) * w).unwrap();
            for (i, g) in grad.iter().enumerate() {
                let y = first + i / w;
                if !(top..bottom).contains(&y) {
                    assert_eq!(
                        g, &[0.0; 4],
                        "limit {limit:?} row {y}: a halo row's gradient"
                    );
                    continue;
                }
                scored_rows += usize::from(i % w == 0);
                let r = ref_grad[y * w + i % w];
                for k in 0..3 {
                    let err = (f64::from(g[k]) - r[k]).abs();
                    assert!(
                        err <= 1e-4 * r[k].abs() + 1e-6 * scale,
                        "limit {limit:?} row {y} column {} channel {k}: {} vs {}",
                        i % w,
                        g[k],
                        r[k]
                    );
                }
            }
        }
        assert_eq!(scored_rows, h);
        // The bands' losses are parts of the frame's: (1 − λ)·L1 + λ·(1 − SSIM) adds up once
        // the constant λ is counted once.
        let parts = total - 2.0 * f64::from(lambda);
        assert!(
            (parts - ref_loss).abs() < 1e-5 * ref_loss,
            "limit {limit:?}: bands {parts} vs frame {ref_loss}"
        );
    }
}
