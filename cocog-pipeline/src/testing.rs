//! Fixtures for stage tests: the smallest scene that validates.

use crate::scene::{Camera, Scene, Split, View};

/// One 4×3 pinhole camera (f = 2, centred principal point) and one train view `a.png` at the
/// identity pose; callers add what their stage reads (points, Gaussians, bounds).
pub fn one_view_scene() -> Scene {
    let mut world_from_camera = [[0.0; 4]; 4];
    for (i, row) in world_from_camera.iter_mut().enumerate() {
        row[i] = 1.0;
    }
    Scene {
        cameras: vec![Camera {
            id: 1,
            width: 4,
            height: 3,
            fx: 2.0,
            fy: 2.0,
            cx: 2.0,
            cy: 1.5,
        }],
        views: vec![View {
            name: "a.png".into(),
            image: "a.png".into(),
            camera: 1,
            world_from_camera,
            split: Split::Train,
            lens: None,
            depth: None,
        }],
        ..Scene::default()
    }
}
