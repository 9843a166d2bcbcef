//! The thin-lens invariant: a surface on the focal plane renders identically with and without
//! an aperture, while the same surface off the plane is blurred.

use cocog_engine::Camera;
use cocog_engine::reference::render;
use cocog_synth::{BlurSpace, SceneBuilder, ThinLens, render_thin_lens};
use glam::DVec3;

const FOCUS: f64 = 1.2;

fn camera() -> Camera {
    Camera {
        fx: 60.0,
        fy: 60.0,
        cx: 24.0,
        cy: 18.0,
        width: 48,
        height: 36,
        // Identity: OpenCV camera at the origin looking down world +z.
        world_from_camera: [
            [1.0, 0.0, 0.0, 0.0],
            [0.0, 1.0, 0.0, 0.0],
            [0.0, 0.0, 1.0, 0.0],
            [0.0, 0.0, 0.0, 1.0],
        ],
    }
}

/// One small disc facing the camera at depth `z`, slightly off axis.
fn disc_at(z: f64) -> cocog_synth::Scene {
    let mut sb = SceneBuilder::new();
    let sigma = 0.02 * z;
    let centre = DVec3::new(0.05 * z, -0.03 * z, z);
    sb.disc(
        centre,
        DVec3::Z,
        DVec3::X,
        [sigma, 0.7 * sigma],
        [0.9, 0.3, 0.1],
        0.95,
    );
    sb.finish([0.1, 0.1, 0.2])
}

fn max_diff(a: &[[f64; 3]], b: &[[f64; 3]]) -> f64 {
    a.iter()
        .flatten()
        .zip(b.iter().flatten())
        .fold(0.0, |m, (x, y)| m.max((x - y).abs()))
}

#[test]
fn in_focus_point_is_unchanged_by_the_aperture() {
    let cam = camera();
    let lens = ThinLens {
        focus_distance: FOCUS,
        aperture_radius: 0.04,
    };
    for space in [BlurSpace::Linear, BlurSpace::Display] {
        let on = disc_at(FOCUS);
        let sharp = render(&on.gaussians, &cam, on.background).color;
        let lens_img = render_thin_lens(&on.gaussians, &cam, Some(lens), 32, on.background, space);
        // The disc's hairline thickness is the only thing that sees the aperture shift.
        let d = max_diff(&sharp, &lens_img);
        assert!(d < 1e-4, "{space:?}: in-focus disc changed by {d}");

        // Control: the same disc at twice the focus distance has a CoC of about 2 px.
        let off = disc_at(2.0 * FOCUS);
        let coc = lens.coc_px(cam.fx, 2.0 * FOCUS);
        assert!(coc > 1.5, "{coc}");
        let sharp = render(&off.gaussians, &cam, off.background).color;
        let lens_img =
            render_thin_lens(&off.gaussians, &cam, Some(lens), 32, off.background, space);
        let d = max_diff(&sharp, &lens_img);
        assert!(d > 0.05, "{space:?}: out-of-focus disc only changed by {d}");
    }
}

#[test]
fn no_aperture_is_a_pinhole_render() {
    let cam = camera();
    let s = disc_at(2.0);
    let pinhole = render(&s.gaussians, &cam, s.background).color;
    let zero = ThinLens {
        focus_distance: 1.0,
        aperture_radius: 0.0,
    };
    for lens in [None, Some(zero)] {
        let img = render_thin_lens(
            &s.gaussians,
            &cam,
            lens,
            16,
            s.background,
            BlurSpace::Linear,
        );
        assert_eq!(img, pinhole);
    }
}
