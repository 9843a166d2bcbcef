//! Bounded proptest fuzzing of the remaining binary readers (.npy, .exr): mutated valid files
//! must give an error or a value, never a panic.

use cocog_formats::exr_map::{FloatMap, read_exr, write_exr};
use cocog_formats::llff::{LlffView, read_poses_bounds, write_poses_bounds};
use proptest::prelude::*;

fn mutate(mut bytes: Vec<u8>, cut: usize, flips: &[(usize, u8)]) -> Vec<u8> {
    for (at, v) in flips {
        if let Some(b) = bytes.get_mut(*at) {
            *b = *v;
        }
    }
    bytes.truncate(cut.min(bytes.len()));
    bytes
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, failure_persistence: None, ..ProptestConfig::default() })]

    #[test]
    fn npy_reader_never_panics(cut in 0usize..600, flips in proptest::collection::vec((0usize..600, any::<u8>()), 0..6)) {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("poses_bounds.npy");
        let eye = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]];
        let v = LlffView { world_from_camera: eye, hwf: [3.0, 4.0, 5.0], near: 0.1, far: 9.0 };
        write_poses_bounds(&p, &[v, v, v]).unwrap();
        let bytes = mutate(std::fs::read(&p).unwrap(), cut, &flips);
        std::fs::write(&p, bytes).unwrap();
        let _ = read_poses_bounds(&p);
    }

    #[test]
    fn exr_reader_never_panics(cut in 0usize..700, flips in proptest::collection::vec((0usize..700, any::<u8>()), 0..4)) {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("d.exr");
        write_exr(&p, &FloatMap { width: 5, height: 4, data: (0..20).map(|i| i as f32).collect() }).unwrap();
        let bytes = mutate(std::fs::read(&p).unwrap(), cut, &flips);
        std::fs::write(&p, bytes).unwrap();
        let _ = read_exr(&p);
    }
}
