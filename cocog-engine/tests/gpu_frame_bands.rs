//! Frames rendered in bands of rows, as a frame too large for one buffer binding is, against
//! the f64 reference of the whole frame: with the binding limit lowered so tiny frames band
//! by their colour buffer or by their tile intersections (Gaussians straddling band edges,
//! and centred off the frame, where the projection's clamp must use the frame's edges), and
//! once at the adapter's own limit where that is small enough to fill (lavapipe: 128 MiB).

mod common;

use cocog_engine::reference::{Gaussians64, Image64, render};
use cocog_engine::{
    Batch, Camera, EngineError, Frame, GaussianParams, GpuContext, ImageSpec, ParamBuffers,
    RenderedImage, Renderer,
};
use common::{Rng, gpu, random_scene, test_camera};

const BACKGROUND: [f32; 3] = [0.1, 0.2, 0.3];

fn render_frame(
    ctx: &GpuContext,
    renderer: &Renderer,
    g: &GaussianParams,
    cam: &Camera,
) -> Result<Frame, EngineError> {
    let spec = ImageSpec {
        camera: *cam,
        background: BACKGROUND,
        first: 0,
        count: g.len() as u32,
        crop: None,
    };
    let mut batch = Batch::new(ctx, ParamBuffers::upload(ctx, &[g]).unwrap(), vec![spec])?;
    renderer.render_frame(ctx, &mut batch, spec)
}

/// Largest per-pixel difference of `img` from rows `first_row..` of `reference`:
/// (colour, alpha, depth relative to its size).
fn worst(img: &RenderedImage, first_row: u32, reference: &Image64) -> [f64; 3] {
    assert_eq!(img.width, reference.width);
    let offset = (first_row * img.width) as usize;
    let mut worst = [0.0f64; 3];
    for (p, r) in (offset..).zip(0..reference.color.len()) {
        for k in 0..3 {
            worst[0] = worst[0].max((f64::from(img.color[p][k]) - reference.color[r][k]).abs());
        }
        worst[1] = worst[1].max((f64::from(img.alpha[p]) - reference.alpha[r]).abs());
        let d = reference.depth[r];
        worst[2] = worst[2].max((f64::from(img.depth[p]) - d).abs() / d.abs().max(1.0));
    }
    worst
}

/// Over all pixels and channels of colour and alpha: the fraction off the reference by more
/// than 1e-4, and the mean absolute difference.
fn off_fraction(img: &RenderedImage, first_row: u32, reference: &Image64) -> (f64, f64) {
    let offset = (first_row * img.width) as usize;
    let (mut off, mut sum, mut n) = (0usize, 0.0f64, 0usize);
    for (p, r) in (offset..).zip(0..reference.color.len()) {
        let c = img.color[p];
        let diffs: [f64; 4] = std::array::from_fn(|k| match k {
            3 => (f64::from(img.alpha[p]) - reference.alpha[r]).abs(),
            k => (f64::from(c[k]) - reference.color[r][k]).abs(),
        });
        for d in diffs {
            off += usize::from(d > 1e-4);
            sum += d;
            n += 1;
        }
    }
    (off as f64 / n as f64, sum / n as f64)
}

fn assert_close(img: &RenderedImage, first_row: u32, reference: &Image64, what: &str) {
    let [c, a, d] = worst(img, first_row, reference);
    eprintln!("{what}: max |Δ| colour {c:.2e}, alpha {a:.2e}, depth {d:.2e}");
    assert!(
        c < 1e-4 && a < 1e-4 && d < 1e-4,
        "{what}: differs from the reference"
    );
}

/// A world point `z` in front of `cam` that projects to pixel position (u, v).
fn at_pixel(cam: &Camera, u: f64, v: f64, z: f64) -> [f32; 3] {
    let p = [z * (u - cam.cx) / cam.fx, z * (v - cam.cy) / cam.fy, z];
    let m = cam.world_from_camera;
    std::array::from_fn(|r| (m[r][0] * p[0] + m[r][1] * p[1] + m[r][2] * p[2] + m[r][3]) as f32)
}

/// `random_scene` plus large Gaussians centred up to 0.3 frame heights above and below the
/// frame: their footprints reach into the frame, and a band would clamp them differently.
fn tall_scene(cam: &Camera, n: usize, seed: u64) -> GaussianParams {
    let mut g = random_scene(n, 1, seed, cam);
    let mut rng = Rng::new(seed + 1);
    let h = f64::from(cam.height);
    for i in 0..n / 4 {
        let v = if i % 2 == 0 {
            rng.range(-0.3 * h, 0.0)
        } else {
            rng.range(h, 1.3 * h)
        };
        g.means.push(at_pixel(
            cam,
            rng.range(0.0, f64::from(cam.width)),
            v,
            rng.range(1.5, 3.0),
        ));
        g.log_scales
            .push(std::array::from_fn(|_| rng.range_f32(-2.0, -1.2)));
        g.quats
            .push(std::array::from_fn(|_| rng.range_f32(-1.0, 1.0)));
        g.opacity_logits.push(rng.range_f32(-1.0, 2.0));
        // Degree 1: 3 × 4 coefficients, copied from the last random Gaussian.
        let last = g.sh[g.sh.len() - 12..].to_vec();
        g.sh.extend(last);
    }
    g
}

#[test]
fn frames_in_bands_of_rows_match_the_whole_frame() {
    let Some(ctx) = gpu() else { return };
    // 88 rows: five whole 16-row bands and an 8-row one.
    let cam = test_camera(48, 88, 0.2);
    let g = tall_scene(&cam, 160, 31);
    let reference = render(&Gaussians64::from(&g), &cam, BACKGROUND.map(f64::from));
    let whole = render_frame(ctx, &Renderer::new(ctx), &g, &cam).unwrap();
    assert_eq!(whole.bands, 1);
    assert_close(&whole.image, 0, &reference, "whole");
    let row_bytes = 16 * u64::from(cam.width);
    // A limit of 40 rows of colour leaves 32-row bands (whole tile rows), 16 rows 16-row bands.
    for (limit_rows, bands) in [(40, 3), (16, 6)] {
        let renderer = Renderer::new(ctx).with_binding_limit(limit_rows * row_bytes);
        let frame = render_frame(ctx, &renderer, &g, &cam).unwrap();
        assert_eq!(frame.bands, bands, "limit of {limit_rows} rows");
        assert_eq!((frame.image.width, frame.image.height), (48, 88));
        assert_close(&frame.image, 0, &reference, &format!("{bands} bands"));
        let [c, a, _] = worst(&frame.image, 0, &whole_as_reference(&whole.image));
        assert!(
            c < 1e-5 && a < 1e-5,
            "{bands} bands differ from the whole frame"
        );
    }
    let covered = reference.alpha.iter().filter(|&&a| a > 0.5).count();
    assert!(covered * 3 > reference.alpha.len(), "scene too sparse");
}

fn whole_as_reference(img: &RenderedImage) -> Image64 {
    Image64 {
        width: img.width,
        height: img.height,
        color: img.color.iter().map(|c| c.map(f64::from)).collect(),
        alpha: img.alpha.iter().map(|&a| f64::from(a)).collect(),
        depth: img.depth.iter().map(|&d| f64::from(d)).collect(),
    }
}

#[test]
fn bands_halve_while_their_intersections_do_not_fit() {
    let Some(ctx) = gpu() else { return };
    // One tile wide, four tall; 1200 Gaussians each wide enough to cover the whole frame.
    let cam = test_camera(16, 64, 0.1);
    let mut rng = Rng::new(5);
    let mut g = random_scene(1200, 0, 6, &cam);
    for (mean, s) in g.means.iter_mut().zip(&mut g.log_scales) {
        // Distinct depths: ties would leave the compositing order to f32 rounding.
        let z = rng.range(2.5, 3.5);
        *mean = at_pixel(&cam, rng.range(4.0, 12.0), rng.range(24.0, 40.0), z);
        // σ ≈ 13–19 pixels: every footprint covers all four tiles.
        *s = [(16.0 * z / cam.fx).ln() as f32; 3];
    }
    for o in &mut g.opacity_logits {
        *o = -4.0; // faint, so the composite runs through most of the list
    }
    let reference = render(&Gaussians64::from(&g), &cam, BACKGROUND.map(f64::from));
    // Colour fits whole (64 rows of 16 pixels), but 4 × 1200 keys do not fit 4096: two
    // 32-row bands of 2400 do.
    let limit = 16 * 16 * 64;
    let renderer = Renderer::new(ctx).with_binding_limit(limit);
    assert_eq!(renderer.max_intersections(ctx), 4096);
    let frame = render_frame(ctx, &renderer, &g, &cam).unwrap();
    assert_eq!(frame.bands, 2);
    assert_close(&frame.image, 0, &reference, "halved bands");
    // A 16-row band of 1200 keys cannot fit 1024: a clear error, not a wgpu panic.
    let tiny = Renderer::new(ctx).with_binding_limit(4096);
    match render_frame(ctx, &tiny, &g, &cam) {
        Err(EngineError::TooManyIntersections { needed, most }) => {
            assert_eq!((needed, most), (1200, 1024));
        }
        other => panic!(
            "expected TooManyIntersections, got {:?}",
            other.map(|f| f.bands)
        ),
    }
}

#[test]
fn a_frame_larger_than_the_adapters_binding_limit_renders() {
    let Some(ctx) = gpu() else { return };
    let renderer = Renderer::new(ctx);
    let limit = renderer.binding_limit(ctx);
    if limit > 256 << 20 {
        eprintln!(
            "skipped: this adapter binds {} MiB, so a frame beyond it would be gigabytes; the \
             lowered-limit tests cover the same code",
            limit >> 20
        );
        return;
    }
    // 2048 wide, one tile row more than the colour buffer's binding holds.
    let width = 2048u32;
    let height = u32::try_from(limit / (16 * u64::from(width))).unwrap() / 16 * 16 + 16;
    let cam = test_camera(width, height, 0.2);
    // Gaussians around three windows of 128 rows: the top, the middle, and the bottom, which
    // holds the band edge 16 rows from the end. A cropped camera gives each window's
    // reference. Windows start on tile rows: tiles decide which Gaussians a pixel sees past
    // 3σ, so only an aligned crop sees what the frame sees. And no Gaussian reaching a window
    // (3σ under 30 pixels) is centred far enough past its edge (0.3 × 128 = 38 pixels) for
    // the projection's clamp to tell the crop from the frame.
    let windows = [0, height / 32 * 16 - 64, height - 128];
    let mut rng = Rng::new(77);
    let mut g = random_scene(3000, 0, 78, &cam);
    for (i, (mean, s)) in g.means.iter_mut().zip(&mut g.log_scales).enumerate() {
        let top = f64::from(windows[i % 3]);
        let z = rng.range(1.5, 3.0);
        *mean = at_pixel(
            &cam,
            rng.range(0.0, f64::from(width)),
            rng.range(top, top + 128.0),
            z,
        );
        let sigma_px = rng.range(3.0, 9.0);
        *s = [(sigma_px * z / cam.fx).ln() as f32; 3];
    }
    let frame = render_frame(ctx, &renderer, &g, &cam).unwrap();
    assert!(16 * u64::from(width) * u64::from(height) > limit);
    assert_eq!(frame.bands, 2);
    assert_eq!((frame.image.width, frame.image.height), (width, height));
    let g64 = Gaussians64::from(&g);
    for top in windows {
        let mut crop = cam;
        crop.cy -= f64::from(top);
        crop.height = 128;
        let reference = render(&g64, &crop, BACKGROUND.map(f64::from));
        let covered = reference.alpha.iter().filter(|&&a| a > 0.1).count();
        assert!(
            covered * 4 > reference.alpha.len(),
            "window at {top} too sparse"
        );
        // f32 pixel positions near 2048–4096 resolve 2.4e-4–4.9e-4 pixels, enough to move a
        // pixel's alpha across compositing's 1/255 cut-off where the f64 reference sits
        // next to it: such a pixel gains or loses one layer of at most 1/255. Those are
        // rare; a misplaced band or a wrong clamp spoils whole rows or footprints.
        let [c, a, d] = worst(&frame.image, top, &reference);
        let (off, mean) = off_fraction(&frame.image, top, &reference);
        eprintln!(
            "rows {top}..: max |Δ| colour {c:.2e}, alpha {a:.2e}, depth {d:.2e}; {:.4}% of \
             values off by > 1e-4, mean |Δ| {mean:.1e}",
            100.0 * off
        );
        assert!(
            c < 5e-3 && a < 5e-3,
            "rows {top}..: more than one layer off"
        );
        assert!(
            off < 1e-3 && mean < 1e-5,
            "rows {top}..: differ from the reference"
        );
    }
    // No Gaussian lies between the windows: those rows show the background alone.
    for row in [height / 4, height * 3 / 4] {
        let p = (row * width + width / 2) as usize;
        assert_eq!(frame.image.alpha[p], 0.0);
        assert_eq!(frame.image.color[p], BACKGROUND);
    }
}
