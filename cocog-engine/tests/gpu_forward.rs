//! GPU forward images against the f64 CPU reference, single images and batches.

mod common;

use cocog_engine::reference::{Gaussians64, render};
use cocog_engine::{Batch, Camera, GaussianParams, RasterBlocks, RasterSplit, Renderer, View};
use common::{gpu, random_scene, scenes_per_camera, test_camera, views_of};

/// Renders `views` in one GPU batch and compares every image with the reference.
fn compare(views: &[View<'_>]) {
    compare_with(views, 0.5);
}

/// `compare`, where more than `min_visible` of each view's Gaussians must be visible.
fn compare_with(views: &[View<'_>], min_visible: f64) {
    compare_in_blocks(views, min_visible, RasterBlocks::DEFAULT);
}

/// `compare_with`, compositing in workgroups of these blocks.
fn compare_in_blocks(views: &[View<'_>], min_visible: f64, blocks: RasterBlocks) {
    let Some(ctx) = gpu() else { return };
    compare_on(
        views,
        min_visible,
        Renderer::new(ctx).with_raster_blocks(blocks),
    );
}

/// `compare_with` on `renderer`.
fn compare_on(views: &[View<'_>], min_visible: f64, renderer: Renderer) {
    let Some(ctx) = gpu() else { return };
    let batch = Batch::from_views(ctx, views).unwrap();
    let state = renderer.forward(ctx, &batch).unwrap();
    assert!(state.num_intersections > 0);
    let images = state.read_images(ctx, &batch).unwrap();
    let projected: Vec<[f32; 12]> = ctx
        .read(&state.projected, batch.params.num_gaussians as usize)
        .unwrap();
    for (i, (view, img)) in views.iter().zip(&images).enumerate() {
        let bg = view.background.map(f64::from);
        let g64 = Gaussians64::from(view.gaussians);
        let reference = render(&g64, view.camera, bg);
        // Visibility and screen footprint, as densification will read them. The GPU may also
        // drop Gaussians the reference keeps when they reach no pixel above 1/255.
        let first = batch.images[i].first as usize;
        let mut visible = 0;
        for (j, p) in projected[first..first + view.gaussians.len()]
            .iter()
            .enumerate()
        {
            match cocog_engine::reference::project(&g64, j, view.camera) {
                Some(r) if p[7] > 0.0 => {
                    visible += 1;
                    assert!(
                        (f64::from(p[0]) - r.mean2d[0]).abs() < 1e-3,
                        "mean2d of {j}"
                    );
                    assert!(
                        (f64::from(p[2]) - r.depth).abs() < 1e-5 * r.depth,
                        "depth of {j}"
                    );
                }
                Some(_) => {}
                None => assert_eq!(p[7], 0.0, "culled Gaussian {j} has a radius"),
            }
        }
        assert!(
            visible as f64 > min_visible * view.gaussians.len() as f64,
            "only {visible} Gaussians visible"
        );
        let (mut worst_c, mut worst_a, mut worst_d) = (0.0f64, 0.0f64, 0.0f64);
        for p in 0..img.color.len() {
            for k in 0..3 {
                worst_c = worst_c.max((f64::from(img.color[p][k]) - reference.color[p][k]).abs());
            }
            worst_a = worst_a.max((f64::from(img.alpha[p]) - reference.alpha[p]).abs());
            // Depth is a sum of z values (~3), so compare relative to its size.
            let d = reference.depth[p];
            worst_d = worst_d.max((f64::from(img.depth[p]) - d).abs() / d.abs().max(1.0));
        }
        eprintln!(
            "image {i}: max |Δ| colour {worst_c:.2e}, alpha {worst_a:.2e}, depth {worst_d:.2e}"
        );
        assert!(worst_c < 1e-4, "image {i}: colour differs by {worst_c}");
        assert!(worst_a < 1e-4, "image {i}: alpha differs by {worst_a}");
        assert!(worst_d < 1e-4, "image {i}: depth differs by {worst_d}");
        let covered = reference.alpha.iter().filter(|&&a| a > 0.5).count();
        assert!(
            covered * 4 > reference.alpha.len(),
            "scene too sparse to test anything"
        );
    }
}

#[test]
fn forward_matches_reference_every_sh_degree() {
    let cam = test_camera(64, 48, 0.2);
    for degree in 0..=3 {
        let g = random_scene(80, degree, 100 + u64::from(degree), &cam);
        compare(&[View {
            gaussians: &g,
            camera: &cam,
            background: [0.1, 0.6, 0.3],
        }]);
    }
}

#[test]
fn batch_renders_separate_images_in_one_launch() {
    // Different Gaussian sets, cameras and backgrounds per image, and an odd size so tiles
    // are partial on both axes.
    let (cams, sets) = scenes_per_camera(3, (50, 37), 0.1, 2, |i| 90 + 10 * i, 7);
    let views = views_of(&cams, &sets, |i| {
        [0.2 * i as f32, 0.5, 1.0 - 0.3 * i as f32]
    });
    compare(&views);
}

/// Two thirds of the Gaussians culled, interleaved with the visible ones (behind the camera, or
/// far beside the frame): the depth sort drops them in its first pass and sorts the rest in
/// later passes whose trailing blocks hold nothing, so order and pixels must still match.
#[test]
fn mostly_culled_scene_matches_reference() {
    let cam = test_camera(64, 48, 0.2);
    let mut g = random_scene(3000, 1, 41, &cam);
    let m = cam.world_from_camera;
    for (i, p) in g.means.iter_mut().enumerate() {
        for r in 0..3 {
            let (centre, side) = (m[r][3] as f32, m[r][0] as f32);
            match i % 3 {
                1 => p[r] = 2.0 * centre - p[r],
                2 => p[r] += 10.0 * side,
                _ => {}
            }
        }
    }
    let g64 = Gaussians64::from(&g);
    let seen = (0..g.len())
        .filter(|&i| cocog_engine::reference::project(&g64, i, &cam).is_some())
        .count();
    assert!(seen <= 1000, "{seen} Gaussians project into the frame");
    compare_with(
        &[View {
            gaussians: &g,
            camera: &cam,
            background: [0.3, 0.2, 0.9],
        }],
        0.3,
    );
}

/// 400 near-opaque Gaussians before a 64×48 camera: most pixels' transmittance runs out.
fn dense_scene() -> (GaussianParams, Camera) {
    let cam = test_camera(64, 48, 0.0);
    let mut g = random_scene(400, 1, 5, &cam);
    for o in &mut g.opacity_logits {
        *o += 3.0;
    }
    (g, cam)
}

#[test]
fn dense_scene_hits_early_termination() {
    let (g, cam) = dense_scene();
    let opaque = render(&Gaussians64::from(&g), &cam, [1.0; 3])
        .alpha
        .iter()
        .filter(|&&a| a > 0.999)
        .count();
    assert!(
        opaque > 100,
        "only {opaque} pixels near full opacity: termination untested"
    );
    compare(&[View {
        gaussians: &g,
        camera: &cam,
        background: [1.0, 1.0, 1.0],
    }]);
}

/// Also on a frame 10 tiles wide, with the projection and the key emission testing every tile
/// and taking wide rows as spans (`with_tile_spans`, tile_test.wgsl's `row_span`): the same
/// tiles either way.
#[test]
fn tile_culling_drops_intersections_without_changing_pixels() {
    for (w, h, fainter) in [(64, 48, 2.0), (160, 96, 1.0)] {
        let counts = [false, true].map(|spans| tile_culling_case(w, h, fainter, spans));
        assert_eq!(
            counts[0], counts[1],
            "{w}×{h}: intersections scanned vs as spans"
        );
    }
}

/// Spans by default on a GPU, where they halved the binning kernels at 400×300 on an H100,
/// and the scan on a CPU adapter, where spans cost (BENCHMARKS.md, session 42).
#[test]
fn tile_spans_default_by_adapter() {
    let Some(ctx) = gpu() else { return };
    if std::env::var_os("COCOG_TILE_SPANS").is_some() {
        eprintln!("skipped: COCOG_TILE_SPANS is set");
        return;
    }
    assert_eq!(Renderer::new(ctx).tile_spans(), !ctx.is_cpu());
    for spans in [false, true] {
        assert_eq!(
            Renderer::new(ctx).with_tile_spans(ctx, spans).tile_spans(),
            spans
        );
    }
}

/// Elongated Gaussians, their opacity logits lowered by `fainter`: their 3σ boxes cover many
/// tiles they never reach. (On the wide frame, as faint as on the small one, a few pixels meet
/// a Gaussian at exactly 1/255 alpha, which the f32 and f64 cut-offs decide apart.)
fn tile_culling_case(w: u32, h: u32, fainter: f32, spans: bool) -> u32 {
    let Some(ctx) = gpu() else { return 0 };
    let cam = test_camera(w, h, 0.3);
    let mut g = random_scene(150, 0, 31, &cam);
    for (i, s) in g.log_scales.iter_mut().enumerate() {
        s[i % 3] += 1.5;
    }
    for o in &mut g.opacity_logits {
        *o -= fainter;
    }
    let g64 = Gaussians64::from(&g);
    let boxed: u32 = (0..g.len())
        .filter_map(|i| cocog_engine::reference::project(&g64, i, &cam))
        .map(|p| (p.tile_max[0] - p.tile_min[0]) * (p.tile_max[1] - p.tile_min[1]))
        .sum();
    let view = View {
        gaussians: &g,
        camera: &cam,
        background: [0.0; 3],
    };
    let batch = Batch::from_views(ctx, &[view]).unwrap();
    let renderer = || Renderer::new(ctx).with_tile_spans(ctx, spans);
    let k = renderer().forward(ctx, &batch).unwrap().num_intersections;
    eprintln!("{k} intersections after the tile test (spans: {spans}), {boxed} in the 3σ boxes");
    assert!(
        k > 0 && k * 10 < boxed * 9,
        "tile test removed too little: {k} of {boxed}"
    );
    compare_on(&[view], 0.5, renderer());
    k
}

/// Compositing in whole 16×16 tiles and in 8×8 blocks of a tile (the default forward's):
/// a batch of frames whose sides are multiples of neither 8 nor 16, then a dense scene where
/// blocks stop early.
#[test]
fn tiles_and_blocks_match_reference() {
    for side in [16, 8] {
        let (cams, sets) = scenes_per_camera(2, (45, 37), 0.1, 2, |_| 60, 80);
        compare_in_blocks(
            &views_of(&cams, &sets, |i| [0.2, 0.5, 0.3 * i as f32]),
            0.5,
            RasterBlocks::both(side),
        );
        let (g, cam) = dense_scene();
        compare_in_blocks(
            &[View {
                gaussians: &g,
                camera: &cam,
                background: [1.0, 1.0, 1.0],
            }],
            0.5,
            RasterBlocks::both(side),
        );
    }
}

/// Splitting the backward's tile lists (`with_raster_split`) only makes the forward record
/// where each chunk starts: its pixels stay bit for bit those of the unsplit forward, on a dense
/// scene where pixels stop early and on a batch of frames.
#[test]
fn split_lists_leave_the_forward_unchanged() {
    let Some(ctx) = gpu() else { return };
    on_dense_and_ragged(|views| {
        let batch = Batch::from_views(ctx, views).unwrap();
        let render = |split| {
            let renderer = Renderer::new(ctx).with_raster_split(split);
            let state = renderer.forward(ctx, &batch).unwrap();
            state.read_images(ctx, &batch).unwrap()
        };
        let whole = render(RasterSplit::Fixed(1));
        for split in [RasterSplit::Fixed(6), RasterSplit::Auto] {
            assert!(
                render(split) == whole,
                "{split:?} changed the forward's pixels"
            );
        }
    });
}

/// Runs `check` on a dense scene whose pixels stop early, then on a batch of ragged frames.
fn on_dense_and_ragged(check: impl Fn(&[View<'_>])) {
    let (g, cam) = dense_scene();
    check(&[View {
        gaussians: &g,
        camera: &cam,
        background: [1.0, 1.0, 1.0],
    }]);
    let (cams, sets) = scenes_per_camera(2, (45, 37), 0.1, 2, |_| 60, 80);
    check(&views_of(&cams, &sets, |i| [0.2, 0.5, 0.3 * i as f32]));
}

/// A pixel's result does not depend on the forward's block side, which the backward relies on
/// (it reads per-pixel state the forward wrote with another side): 8×8 blocks and whole tiles
/// give the same pixels bit for bit, with and without a split's chunk state, on a dense scene
/// whose blocks stop early and on a batch of ragged frames. Then one renderer choosing the side
/// per pass (`RasterBlocks::AUTO`) renders a small frame in 8×8 blocks and a frame of 2048
/// tiles in whole tiles, each the same pixels as a renderer fixed to that side.
#[test]
fn block_sides_leave_the_pixels_unchanged() {
    let Some(ctx) = gpu() else { return };
    let render = |renderer: &Renderer, views: &[View<'_>]| {
        let batch = Batch::from_views(ctx, views).unwrap();
        let state = renderer.forward(ctx, &batch).unwrap();
        state.read_images(ctx, &batch).unwrap()
    };
    on_dense_and_ragged(|views| {
        for split in [RasterSplit::Fixed(1), RasterSplit::Fixed(5)] {
            let with = |side| {
                Renderer::new(ctx)
                    .with_raster_blocks(RasterBlocks::both(side))
                    .with_raster_split(split)
            };
            assert!(
                render(&with(8), views) == render(&with(16), views),
                "8×8 blocks changed the pixels ({split:?})"
            );
        }
    });
    let auto = Renderer::new(ctx).with_raster_blocks(RasterBlocks::DEFAULT);
    let small = test_camera(64, 48, 0.0);
    let large = test_camera(1024, 512, 0.0);
    assert_eq!(RasterBlocks::DEFAULT.forward_side((4, 3), 1), 8);
    assert_eq!(RasterBlocks::DEFAULT.forward_side((64, 32), 1), 16);
    for (cam, side) in [(&small, 8), (&large, 16), (&small, 8)] {
        let g = random_scene(40, 1, 9, cam);
        let view = [View {
            gaussians: &g,
            camera: cam,
            background: [0.1, 0.2, 0.3],
        }];
        let fixed = Renderer::new(ctx).with_raster_blocks(RasterBlocks::both(side));
        assert!(
            render(&auto, &view) == render(&fixed, &view),
            "the automatic side changed a {}×{} frame's pixels",
            cam.width,
            cam.height
        );
    }
}
