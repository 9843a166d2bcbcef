//! A refocused view renders M + 1 sets at once and, through F, holds the feature maps of as
//! many renders as a binding holds (one at least); it cannot go in bands, so a view whose
//! renders or one render's maps outgrow a buffer binding is refused by name, while its sharp
//! render (aperture 0) still renders in bands.

mod common;

use cocog_engine::coc::{CocConfig, CocVariant, Frame, Lens, Refocus, init_weights};
use cocog_engine::nn::{CompositeMode, CompositorConfig};
use common::{gpu, random_scene, test_camera};

#[test]
fn a_refocused_view_too_large_for_a_binding_is_refused_by_name() {
    let Some(ctx) = gpu() else { return };
    let cam = test_camera(32, 32, 0.1);
    let g = random_scene(40, 1, 3, &cam);
    let config = CocConfig::new(CocVariant::Lens);
    let sets = u64::from(config.copies + 1);
    let mlp = init_weights(&config.mlp(), 1);
    let channels = 4;
    let f = CompositorConfig::with_channels(channels).layout().init(2);
    let frame = Frame {
        origin: [0.0; 3],
        scale: 1.0,
    };
    let refocus = |limit: u64| {
        Refocus::new(ctx, config, channels, frame, &g, &mlp, &f)
            .unwrap()
            .with_binding_limit(limit)
    };
    let lens = |composite| Lens {
        focus_distance: 2.0,
        aperture: 1.0,
        learned_aperture: 0.5,
        composite,
    };
    let pixels = 32 * 32;
    let rgba = 16 * pixels * sets;
    // Exactly enough for the renders: both modes render, F in chunks of its renders (each
    // render's 4-channel maps are a sixth of the renders).
    for mode in [CompositeMode::Learned, CompositeMode::Uniform] {
        let img = refocus(rgba).render(&cam, [0.0; 3], &lens(mode)).unwrap();
        assert_eq!((img.width, img.height), (32, 32));
    }
    // One byte short: refused, naming what needs the room and what to do.
    let err = refocus(rgba - 1)
        .render(&cam, [0.0; 3], &lens(CompositeMode::Uniform))
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("32×32") && err.contains(&format!("{sets} rgba renders")),
        "{err}"
    );
    assert!(err.contains("--downscale 2"), "{err}");
    // 32 channels: one render's maps are 128 floats a pixel, more than the six renders' 96.
    let f32c = CompositorConfig::with_channels(32).layout().init(2);
    let mut wide = Refocus::new(ctx, config, 32, frame, &g, &mlp, &f32c)
        .unwrap()
        .with_binding_limit(rgba);
    let err = wide
        .render(&cam, [0.0; 3], &lens(CompositeMode::Learned))
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("32-channel maps of one render") && err.contains("--composite mean"),
        "{err}"
    );
    // Averaged, the same view fits.
    wide.render(&cam, [0.0; 3], &lens(CompositeMode::Uniform))
        .unwrap();
    // Aperture 0 is the sharp render, which bands: a limit of one tile row of rgba suffices.
    let sharp = Lens {
        aperture: 0.0,
        ..lens(CompositeMode::Learned)
    };
    let img = refocus(16 * 32 * 16)
        .render(&cam, [0.0; 3], &sharp)
        .unwrap();
    assert_eq!((img.width, img.height), (32, 32));
}
