//! Bounded proptest fuzzing of the PLY reader: arbitrary headers and bodies never panic.

use cocog_formats::ply::{read_points, read_splats};
use proptest::prelude::*;

fn header_line() -> impl Strategy<Value = String> {
    prop_oneof![
        Just("format binary_little_endian 1.0".to_owned()),
        Just("format binary_big_endian 1.0".to_owned()),
        Just("format ascii 1.0".to_owned()),
        (0u64..5).prop_map(|n| format!("element vertex {n}")),
        Just("element face 2".to_owned()),
        prop::sample::select(vec![
            "x", "y", "z", "red", "opacity", "f_dc_0", "f_rest_0", "rot_0", "scale_0"
        ])
        .prop_flat_map(|n| prop::sample::select(vec![
            "float", "double", "uchar", "int", "short"
        ])
        .prop_map(move |t| format!("property {t} {n}"))),
        Just("property list uchar int vertex_indices".to_owned()),
        "[ -~]{0,20}",
    ]
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, failure_persistence: None, ..ProptestConfig::default() })]

    #[test]
    fn ply_reader_never_panics(lines in prop::collection::vec(header_line(), 0..12), body in prop::collection::vec(any::<u8>(), 0..256)) {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("f.ply");
        let mut bytes = format!("ply\n{}\nend_header\n", lines.join("\n")).into_bytes();
        bytes.extend(body);
        std::fs::write(&p, &bytes).unwrap();
        let _ = read_splats(&p);
        let _ = read_points(&p);
    }
}
