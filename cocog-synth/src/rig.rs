//! Forward-facing camera rig (LLFF-like) and the per-view lens of each view.

use cocog_engine::Camera;
use cocog_formats::pose::{Mat4, from_rt};
use glam::{DMat3, DVec3};

use crate::SynthConfig;
use crate::lens::ThinLens;
use crate::rng::Rng;

/// Deblur-NeRF's convention: test views are sharp ground truth, train views are defocused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Split {
    Train,
    Test,
}

impl Split {
    pub fn as_str(self) -> &'static str {
        match self {
            Split::Train => "train",
            Split::Test => "test",
        }
    }
}

/// One view to render.
#[derive(Clone, Debug, PartialEq)]
pub struct ViewSpec {
    pub index: usize,
    /// File name inside `images/`, e.g. `003.png`.
    pub name: String,
    pub camera: Camera,
    pub split: Split,
    /// `None` for test views (all in focus).
    pub lens: Option<ThinLens>,
}

/// Centre of the rig; the cameras look from here towards `TARGET`.
const RIG_CENTRE: DVec3 = DVec3::new(0.0, 0.0, 0.5);
const TARGET: DVec3 = DVec3::new(0.0, 1.5, 0.18);
/// Half extents of the camera spread (x, z): a hand-held forward-facing capture.
const SPREAD: [f64; 2] = [0.22, 0.07];

/// OpenCV `world_from_camera` of a camera at `centre` looking at `target`, world z up.
pub fn look_at(centre: DVec3, target: DVec3) -> Mat4 {
    let fwd = (target - centre).normalize();
    let right = fwd.cross(DVec3::Z).normalize();
    let down = fwd.cross(right);
    from_rt(DMat3::from_cols(right, down, fwd), centre)
}

/// Pinhole intrinsics of the configured size and horizontal field of view, centred.
pub fn intrinsics(cfg: &SynthConfig) -> (f64, f64, f64, f64) {
    let fx = 0.5 * f64::from(cfg.width) / (0.5 * cfg.fov_x_deg.to_radians()).tan();
    (
        fx,
        fx,
        0.5 * f64::from(cfg.width),
        0.5 * f64::from(cfg.height),
    )
}

/// Focus distances of the train views: stratified over `focus_range` and shuffled, so a
/// handful of views still covers near, middle and far objects.
fn focus_distances(cfg: &SynthConfig, count: usize) -> Vec<f64> {
    let mut rng = Rng::fork(cfg.seed, 3);
    let [lo, hi] = cfg.focus_range;
    let mut f: Vec<f64> = (0..count)
        .map(|k| lo + (hi - lo) * (k as f64 + rng.unit()) / count as f64)
        .collect();
    rng.shuffle(&mut f);
    f
}

/// Every view of the dataset, in file order.
pub fn view_specs(cfg: &SynthConfig) -> Vec<ViewSpec> {
    let mut rng = Rng::fork(cfg.seed, 2);
    let (fx, fy, cx, cy) = intrinsics(cfg);
    let hold = cfg.hold.max(1);
    let train = (0..cfg.views).filter(|i| i % hold != 0).count();
    let mut focus = focus_distances(cfg, train).into_iter();
    (0..cfg.views)
        .map(|i| {
            // A golden-angle spiral over an ellipse spreads any number of views evenly.
            let r = ((i as f64 + 0.5) / cfg.views as f64).sqrt();
            let th = i as f64 * 2.399_963_229_728_653;
            let centre = RIG_CENTRE
                + DVec3::new(
                    SPREAD[0] * r * th.cos() + 0.01 * rng.normal(),
                    0.03 * rng.normal(),
                    SPREAD[1] * r * th.sin() + 0.01 * rng.normal(),
                );
            let target = TARGET + DVec3::new(0.05 * rng.normal(), 0.0, 0.03 * rng.normal());
            let split = if i % hold == 0 {
                Split::Test
            } else {
                Split::Train
            };
            let lens = match split {
                Split::Test => None,
                Split::Train => focus.next().map(|s| ThinLens {
                    focus_distance: s,
                    aperture_radius: cfg.aperture_radius,
                }),
            };
            ViewSpec {
                index: i,
                name: format!("{i:03}.png"),
                camera: Camera {
                    fx,
                    fy,
                    cx,
                    cy,
                    width: cfg.width,
                    height: cfg.height,
                    world_from_camera: look_at(centre, target),
                },
                split,
                lens,
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use cocog_formats::pose::{check_rigid, to_rt};

    #[test]
    fn look_at_is_an_opencv_pose_facing_the_target() {
        let m = look_at(DVec3::new(0.1, -0.2, 0.4), DVec3::new(0.3, 2.0, 0.1));
        check_rigid(&m, 1e-12).unwrap();
        let (r, c) = to_rt(&m);
        let fwd = (DVec3::new(0.3, 2.0, 0.1) - c).normalize();
        assert!((r.col(2) - fwd).length() < 1e-12);
        // Image "down" points down in the world, image "right" has no vertical component.
        assert!(r.col(1).z < 0.0 && r.col(0).z.abs() < 1e-12);
    }

    #[test]
    fn splits_and_focus_follow_the_hold() {
        let cfg = SynthConfig {
            views: 17,
            ..SynthConfig::default()
        };
        let views = view_specs(&cfg);
        let tests: Vec<usize> = views
            .iter()
            .filter(|v| v.split == Split::Test)
            .map(|v| v.index)
            .collect();
        assert_eq!(tests, [0, 8, 16]);
        assert!(
            views
                .iter()
                .all(|v| v.lens.is_some() == (v.split == Split::Train))
        );
        let mut f: Vec<f64> = views
            .iter()
            .filter_map(|v| v.lens)
            .map(|l| l.focus_distance)
            .collect();
        f.sort_by(f64::total_cmp);
        let [lo, hi] = cfg.focus_range;
        // Stratified: one draw per 1/14 of the range.
        for (k, s) in f.iter().enumerate() {
            let w = (hi - lo) / 14.0;
            assert!(
                *s >= lo + k as f64 * w && *s <= lo + (k + 1) as f64 * w,
                "{f:?}"
            );
        }
    }
}
