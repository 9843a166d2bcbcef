//! Bounded proptest fuzzing of the binary parsers: no input may panic or over-allocate.

use std::path::Path;

use proptest::prelude::*;

use super::bin::{parse_cameras, parse_images, parse_points};
use super::{Camera, CameraModel, Image, Model, Point2D, Point3D, TrackElement};

fn valid_files() -> [Vec<u8>; 3] {
    let model = Model {
        cameras: vec![Camera {
            id: 1,
            model: CameraModel::OpenCv,
            width: 64,
            height: 48,
            params: vec![1.0; 8],
        }],
        images: vec![Image {
            id: 3,
            qvec: [1.0, 0.0, 0.0, 0.0],
            tvec: [0.0; 3],
            camera_id: 1,
            name: "a.png".into(),
            points2d: vec![Point2D {
                xy: [1.0, 2.0],
                point3d_id: Some(7),
            }],
        }],
        points: vec![Point3D {
            id: 7,
            xyz: [1.0; 3],
            rgb: [1, 2, 3],
            error: 0.5,
            track: vec![TrackElement {
                image_id: 3,
                point2d_idx: 0,
            }],
        }],
    };
    let dir = tempfile::tempdir().expect("temp dir");
    super::write_bin(&model, dir.path()).expect("write");
    ["cameras.bin", "images.bin", "points3D.bin"]
        .map(|f| std::fs::read(dir.path().join(f)).expect("read back"))
}

fn parse_all(data: &[u8]) {
    let p = Path::new("fuzz.bin");
    let _ = parse_cameras(p, data);
    let _ = parse_images(p, data);
    let _ = parse_points(p, data);
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, failure_persistence: None, ..ProptestConfig::default() })]

    #[test]
    fn arbitrary_bytes_never_panic(data in proptest::collection::vec(any::<u8>(), 0..512)) {
        parse_all(&data);
    }

    #[test]
    fn mutated_valid_files_never_panic(which in 0usize..3, cut in 0usize..400, flips in proptest::collection::vec((0usize..400, any::<u8>()), 0..4)) {
        let mut data = valid_files()[which].clone();
        for (at, v) in flips {
            if let Some(b) = data.get_mut(at) {
                *b = v;
            }
        }
        data.truncate(cut.min(data.len()));
        parse_all(&data);
    }
}
