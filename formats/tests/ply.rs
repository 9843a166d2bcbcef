//! 3DGS and point-cloud PLY: round trips, plyfile cross-checks both ways, bad input, and speed.

mod common;

use std::path::Path;

use cocog_formats::PointCloud;
use cocog_formats::ply::{read_points, read_splats, write_points, write_splats};
use cocog_formats::splats::{Splats, sh_rest_per_channel};

/// Deterministic pseudo-random floats (xorshift), so failures reproduce.
fn noise(seed: u64) -> impl FnMut() -> f32 {
    let mut s = seed.max(1);
    move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 40) as f32 / (1u64 << 24) as f32 * 4.0 - 2.0
    }
}

fn random_splats(n: usize, degree: u32, seed: u64) -> Splats {
    let mut r = noise(seed);
    let mut v = |k: usize| (0..k).map(|_| r()).collect::<Vec<f32>>();
    Splats {
        means: v(3 * n),
        log_scales: v(3 * n),
        rotations: v(4 * n),
        opacities: v(n),
        sh_dc: v(3 * n),
        sh_rest: v(3 * sh_rest_per_channel(degree) * n),
        sh_degree: degree,
    }
}

/// The INRIA property order of splat `i`, for comparing against what Python sees.
fn inria_row(s: &Splats, i: usize) -> Vec<f32> {
    let k3 = 3 * s.rest_per_channel();
    let mut row = s.means[3 * i..3 * i + 3].to_vec();
    row.extend([0.0; 3]);
    row.extend(&s.sh_dc[3 * i..3 * i + 3]);
    row.extend(&s.sh_rest[k3 * i..k3 * (i + 1)]);
    row.push(s.opacities[i]);
    row.extend(&s.log_scales[3 * i..3 * i + 3]);
    row.extend(&s.rotations[4 * i..4 * i + 4]);
    row
}

#[test]
fn splats_round_trip_every_degree() {
    let dir = tempfile::tempdir().unwrap();
    for degree in 0..=3 {
        let s = random_splats(1000, degree, 7 + u64::from(degree));
        let p = dir.path().join(format!("d{degree}.ply"));
        write_splats(&p, &s, Some("-y")).unwrap();
        let back = read_splats(&p).unwrap();
        assert_eq!(back, s);
        let text = std::fs::read(&p).unwrap();
        let header_end = text.windows(11).position(|w| w == b"end_header\n").unwrap() + 11;
        assert_eq!(
            text.len() - header_end,
            1000 * 4 * (17 + 3 * sh_rest_per_channel(degree))
        );
    }
}

const PLYFILE_READS: &str = r#"
import sys, numpy as np
from plyfile import PlyData
d = PlyData.read(sys.argv[1])
assert not d.text and d.byte_order == '<', (d.text, d.byte_order)
assert [e.name for e in d.elements] == ['vertex']
v = d['vertex']
names = [p.name for p in v.properties]
assert all(v.data.dtype[n] == np.dtype('<f4') for n in names)
np.stack([v[n] for n in names], 1).astype('<f4').tofile(sys.argv[2])
print(' '.join(names))
print('|'.join(d.comments))
"#;

#[test]
fn plyfile_reads_our_splats() {
    if !common::python_has(&["plyfile", "numpy"]) {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    for degree in [0, 1, 3] {
        let s = random_splats(257, degree, 99);
        let p = dir.path().join("s.ply");
        let raw = dir.path().join("s.f32");
        write_splats(&p, &s, Some("y")).unwrap();
        let out = common::run_python(PLYFILE_READS, &[p.to_str().unwrap(), raw.to_str().unwrap()]);
        let mut lines = out.lines();
        let names: Vec<&str> = lines.next().unwrap().split(' ').collect();
        let k3 = 3 * sh_rest_per_channel(degree);
        let mut expect = vec![
            "x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2",
        ]
        .into_iter()
        .map(String::from)
        .collect::<Vec<_>>();
        expect.extend((0..k3).map(|i| format!("f_rest_{i}")));
        expect.extend(
            [
                "opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3",
            ]
            .map(String::from),
        );
        assert_eq!(names, expect);
        let comments = lines.next().unwrap();
        assert!(
            comments.contains(&format!("SH degree: {degree}"))
                && comments.contains("Vertical axis: y"),
            "{comments}"
        );
        let bytes = std::fs::read(&raw).unwrap();
        let vals: Vec<f32> = bytes
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
            .collect();
        let expected: Vec<f32> = (0..s.len()).flat_map(|i| inria_row(&s, i)).collect();
        assert_eq!(vals, expected);
    }
}

/// plyfile writes INRIA-style files in other encodings and types, with extra elements/properties.
const PLYFILE_WRITES: &str = r#"
import sys, numpy as np
from plyfile import PlyData, PlyElement
n, out = 50, sys.argv[1]
rng = np.random.default_rng(5)
names = ['x','y','z','nx','ny','nz','f_dc_0','f_dc_1','f_dc_2'] + [f'f_rest_{i}' for i in range(9)] + ['opacity','scale_0','scale_1','scale_2','rot_0','rot_1','rot_2','rot_3','extra']
vals = rng.standard_normal((n, len(names))).astype('<f4')
vals.tofile(out + '/values.f32')
for kind, dt, text, order in [('le_f', 'f4', False, '<'), ('be_d', 'f8', False, '>'), ('ascii', 'f4', True, '=')]:
    # Shuffle property order to prove lookup is by name.
    perm = list(range(len(names)))[::-1]
    arr = np.empty(n, dtype=[(names[i], order + dt) for i in perm])
    for i in perm:
        arr[names[i]] = vals[:, i]
    faces = PlyElement.describe(np.array([(np.array([0, 1, 2], 'i4'),)], dtype=[('vertex_indices', 'O')]), 'face')
    PlyData([faces, PlyElement.describe(arr, 'vertex')], text=text, byte_order=order if order != '=' else '<').write(f'{out}/{kind}.ply')
"#;

#[test]
fn we_read_plyfile_files_in_any_encoding_and_order() {
    if !common::python_has(&["plyfile", "numpy"]) {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    common::run_python(PLYFILE_WRITES, &[dir.path().to_str().unwrap()]);
    let bytes = std::fs::read(dir.path().join("values.f32")).unwrap();
    let vals: Vec<f32> = bytes
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
        .collect();
    let cols = 27;
    for kind in ["le_f", "be_d", "ascii"] {
        let s = read_splats(&dir.path().join(format!("{kind}.ply")))
            .unwrap_or_else(|e| panic!("{kind}: {e}"));
        assert_eq!((s.len(), s.sh_degree), (50, 1), "{kind}");
        for i in 0..50 {
            let expect = &vals[i * cols..i * cols + cols - 1];
            let got = inria_row(&s, i);
            // Normals are not kept; ascii goes through decimal text, so allow float rounding there.
            for (j, (a, b)) in got
                .iter()
                .zip(expect)
                .enumerate()
                .filter(|(j, _)| !(3..6).contains(j))
            {
                assert!(
                    (a - b).abs() <= 1e-6 * b.abs().max(1.0),
                    "{kind} row {i} col {j}: {a} vs {b}"
                );
            }
        }
    }
}

fn write_raw(dir: &Path, name: &str, bytes: &[u8]) -> std::path::PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, bytes).unwrap();
    p
}

#[test]
fn bad_plys_are_refused_clearly() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let list = write_raw(d, "list.ply", b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty list uchar int idx\nend_header\n1 2 3 4\n");
    let e = read_splats(&list).unwrap_err().to_string();
    assert!(
        e.contains("list.ply") && e.contains("\"idx\"") && e.contains("list property"),
        "{e}"
    );
    let fmt = write_raw(
        d,
        "fmt.ply",
        b"ply\nformat binary_middle_endian 1.0\nelement vertex 0\nend_header\n",
    );
    let e = read_splats(&fmt).unwrap_err().to_string();
    assert!(
        e.contains("fmt.ply") && e.contains("header") && e.contains("binary_middle_endian"),
        "{e}"
    );
    let typ = write_raw(
        d,
        "typ.ply",
        b"ply\nformat ascii 1.0\nelement vertex 0\nproperty float128 x\nend_header\n",
    );
    let e = read_splats(&typ).unwrap_err().to_string();
    assert!(e.contains("float128"), "{e}");
    let nop = write_raw(d, "nop.ply", b"not a ply\n");
    assert!(
        read_splats(&nop)
            .unwrap_err()
            .to_string()
            .contains("header")
    );

    let s = random_splats(10, 1, 3);
    let good = d.join("good.ply");
    write_splats(&good, &s, None).unwrap();
    let bytes = std::fs::read(&good).unwrap();
    let cut = write_raw(d, "cut.ply", &bytes[..bytes.len() - 7]);
    let e = read_splats(&cut).unwrap_err().to_string();
    assert!(
        e.contains("cut.ply")
            && e.contains("element vertex")
            && e.contains("10 declared vertices")
            && e.contains("need 1040 bytes")
            && e.contains("only 1033 remain"),
        "{e}"
    );
    let text = String::from_utf8_lossy(&bytes).replace("property float f_rest_8\n", "");
    let header_only = &text[..text.find("end_header\n").unwrap() + 11];
    let odd = write_raw(
        d,
        "odd.ply",
        header_only
            .replace("element vertex 10", "element vertex 0")
            .as_bytes(),
    );
    let e = read_splats(&odd).unwrap_err().to_string();
    assert!(e.contains("f_rest") && e.contains("got 8"), "{e}");
    let huge = write_raw(
        d,
        "huge.ply",
        &[
            header_only
                .replace("element vertex 10", "element vertex 99999999999")
                .as_bytes(),
            &[0u8; 64],
        ]
        .concat(),
    );
    let e = read_splats(&huge).unwrap_err().to_string();
    assert!(
        e.contains("99999999999 declared vertices") && e.contains("truncated"),
        "{e}"
    );
    // Property-less rows before the vertex cost no bytes but one loop turn each; fuzzing found
    // four billion of them hang the reader.
    let empty_rows = write_raw(
        d,
        "empty-rows.ply",
        b"ply\nformat binary_little_endian 1.0\nelement junk 4000000000\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\nAAAABBBBCCCC",
    );
    let e = read_points(&empty_rows).unwrap_err().to_string();
    assert!(
        e.contains("empty-rows.ply") && e.contains("element junk") && e.contains("cannot fit"),
        "{e}"
    );
    let missing = write_raw(
        d,
        "missing.ply",
        b"ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nend_header\n",
    );
    let e = read_splats(&missing).unwrap_err().to_string();
    assert!(
        e.contains("missing 3DGS properties") && e.contains("opacity"),
        "{e}"
    );
    let compressed = write_raw(d, "c.ply", b"ply\nformat binary_little_endian 1.0\nelement chunk 0\nproperty float min_x\nelement vertex 0\nproperty uint packed_position\nend_header\n");
    assert!(
        read_splats(&compressed)
            .unwrap_err()
            .to_string()
            .contains("compressed")
    );
    let mut bad = s;
    bad.opacities.pop();
    let e = write_splats(&d.join("never.ply"), &bad, None)
        .unwrap_err()
        .to_string();
    assert!(e.contains("opacities") || e.contains("means"), "{e}");
    assert!(!d.join("never.ply").exists());
}

#[test]
fn point_clouds_round_trip_and_plyfile_agrees() {
    let cloud = PointCloud {
        positions: (0..300).map(|i| i as f32 * 0.25 - 7.0).collect(),
        colors: (0..300).map(|i| (i * 7 % 256) as u8).collect(),
    };
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("points.ply");
    write_points(&p, &cloud).unwrap();
    assert_eq!(read_points(&p).unwrap(), cloud);
    if !common::python_has(&["plyfile", "numpy"]) {
        return;
    }
    let script = r#"
import sys, numpy as np
from plyfile import PlyData, PlyElement
v = PlyData.read(sys.argv[1])['vertex']
print(','.join(str(x) for x in np.stack([v['x'], v['y'], v['z']], 1).ravel()[:6]))
print(','.join(str(int(x)) for x in np.stack([v['red'], v['green'], v['blue']], 1).ravel()))
# A float-coloured cloud without normals, as some tools write.
arr = np.array([(1.0, 2.0, 3.0, 1.0, 0.5, 0.0)], dtype=[(n, 'f8') for n in ['x','y','z','red','green','blue']])
PlyData([PlyElement.describe(arr, 'vertex')]).write(sys.argv[2])
"#;
    let q = dir.path().join("float.ply");
    let out = common::run_python(script, &[p.to_str().unwrap(), q.to_str().unwrap()]);
    let mut lines = out.lines();
    let xyz: Vec<f32> = lines
        .next()
        .unwrap()
        .split(',')
        .map(|v| v.parse().unwrap())
        .collect();
    assert_eq!(xyz, cloud.positions[..6]);
    let rgb: Vec<u8> = lines
        .next()
        .unwrap()
        .split(',')
        .map(|v| v.parse().unwrap())
        .collect();
    assert_eq!(rgb, cloud.colors);
    let f = read_points(&q).unwrap();
    assert_eq!(
        (f.positions, f.colors),
        (vec![1.0, 2.0, 3.0], vec![255, 128, 0])
    );
}

/// Overwrites vertex `v`'s values from column `col` on in a binary little-endian splat PLY
/// (SH degree 1: 26 floats a row).
fn patch_row(path: &Path, v: usize, col: usize, vals: &[f32]) {
    let mut bytes = std::fs::read(path).unwrap();
    let end = b"end_header\n";
    let body = bytes.windows(end.len()).position(|w| w == end).unwrap() + end.len();
    for (k, x) in vals.iter().enumerate() {
        let at = body + 4 * (26 * v + col + k);
        bytes[at..at + 4].copy_from_slice(&x.to_le_bytes());
    }
    std::fs::write(path, bytes).unwrap();
}

#[test]
fn non_finite_or_zero_rotation_splats_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let good = random_splats(20, 1, 11);
    // (name, vertex, first column, values, the reader's message); columns at SH degree 1:
    // x y z nx ny nz f_dc_0..2 f_rest_0..8 opacity scale_0..2 rot_0..3.
    let cases: [(&str, usize, usize, &[f32], &str); 7] = [
        ("x", 17, 0, &[f32::NAN], "vertex 17: x is NaN"),
        ("z", 2, 2, &[f32::INFINITY], "vertex 2: z is inf"),
        ("opacity", 5, 18, &[f32::NAN], "vertex 5: opacity is NaN"),
        (
            "scale",
            9,
            20,
            &[f32::NEG_INFINITY],
            "vertex 9: scale_1 is -inf",
        ),
        ("rot", 4, 25, &[f32::NAN], "vertex 4: rot_3 is NaN"),
        ("rest", 6, 17, &[f32::NAN], "vertex 6: f_rest_8 is NaN"),
        (
            "zero",
            3,
            22,
            &[0.0; 4],
            "vertex 3: rot_0..rot_3 are all zero",
        ),
    ];
    for (name, v, col, vals, expect) in cases {
        let p = d.join(format!("gaussians-{name}.ply"));
        write_splats(&p, &good, None).unwrap();
        patch_row(&p, v, col, vals);
        let e = read_splats(&p).unwrap_err().to_string();
        assert!(
            e.contains(&format!("gaussians-{name}.ply")) && e.contains(expect),
            "{name}: {e}"
        );
    }
    // The writer refuses what the reader would, naming the value, and leaves no file.
    type Spoil = fn(&mut Splats);
    let spoiled: [(Spoil, &str); 3] = [
        (
            |s| s.means[3 * 17] = f32::NAN,
            "splats.means[51]: is NaN or infinite",
        ),
        (
            |s| s.sh_rest[9 * 6 + 8] = f32::NEG_INFINITY,
            "splats.sh_rest[62]: is NaN or infinite",
        ),
        (
            |s| s.rotations[4 * 3..4 * 3 + 4].fill(0.0),
            "splats.rotations[12..16]: all zero, expected a rotation quaternion",
        ),
    ];
    for (spoil, expect) in spoiled {
        let mut s = good.clone();
        spoil(&mut s);
        let p = d.join("refused.ply");
        let e = write_splats(&p, &s, None).unwrap_err().to_string();
        assert!(e.contains("refused.ply") && e.contains(expect), "{e}");
        assert!(!p.exists());
    }
    // A quaternion that is zero in all but one component is a valid (unnormalised) rotation.
    let mut s = good;
    s.rotations[0..4].copy_from_slice(&[0.0, 0.0, -0.0, 1e-30]);
    let p = d.join("ok.ply");
    write_splats(&p, &s, None).unwrap();
    assert_eq!(read_splats(&p).unwrap(), s);
}

#[test]
fn point_clouds_refuse_only_non_finite_values() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // Positions far away, duplicates and black points are all fine for SfM points.
    let cloud = PointCloud {
        positions: vec![1e30, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0],
        colors: vec![0; 9],
    };
    let p = d.join("points.ply");
    write_points(&p, &cloud).unwrap();
    assert_eq!(read_points(&p).unwrap(), cloud);
    let mut nan = cloud;
    nan.positions[4] = f32::NAN;
    write_points(&p, &nan).unwrap();
    let e = read_points(&p).unwrap_err().to_string();
    assert!(
        e.contains("points.ply") && e.contains("vertex 1: y is NaN"),
        "{e}"
    );
    let float_colour = write_raw(
        d,
        "float.ply",
        b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nproperty float red\nproperty float green\nproperty float blue\nend_header\n0 0 0 1 1 1\n0 0 0 0.5 nan 0\n",
    );
    let e = read_points(&float_colour).unwrap_err().to_string();
    assert!(e.contains("vertex 1: green is NaN"), "{e}");
}

/// A binary little-endian xyz PLY of `declared` vertices holding `actual` vertices' bytes.
fn xyz_ply(declared: usize, actual: usize, before: &str) -> Vec<u8> {
    let mut b = format!(
        "ply\nformat binary_little_endian 1.0\n{before}element vertex {declared}\nproperty float x\nproperty float y\nproperty float z\nend_header\n"
    )
    .into_bytes();
    for i in 0..3 * actual {
        b.extend_from_slice(&(i as f32).to_le_bytes());
    }
    b
}

#[test]
fn bytes_after_the_declared_elements_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // The audit's file: 100 declared, 2189 present.
    let p = write_raw(d, "short-count.ply", &xyz_ply(100, 2189, ""));
    let e = read_points(&p).unwrap_err().to_string();
    assert!(
        e.contains("short-count.ply")
            && e.contains(&format!(
                "{} bytes after the 100 declared vertices",
                2089 * 12
            ))
            && e.contains("exactly 2089 more vertices")
            && e.contains("`element vertex` count is probably wrong"),
        "{e}"
    );
    // Less than a row left over (a final newline, padding) is no sign of a wrong count, and
    // plyfile, tinyply and Open3D read such files: so does this.
    let mut odd = xyz_ply(3, 3, "");
    odd.push(b'\n');
    let p = write_raw(d, "newline.ply", &odd);
    assert_eq!(read_points(&p).unwrap().len(), 3);
    // The same for splats.
    let s = random_splats(10, 0, 5);
    let good = d.join("good.ply");
    write_splats(&good, &s, None).unwrap();
    let bytes = std::fs::read(&good).unwrap();
    let text = String::from_utf8_lossy(&bytes);
    let header_end = text.find("end_header\n").unwrap() + 11;
    let fewer = [
        text[..header_end]
            .replace("element vertex 10", "element vertex 7")
            .as_bytes(),
        &bytes[header_end..],
    ]
    .concat();
    let p = write_raw(d, "gaussians.ply", &fewer);
    let e = read_splats(&p).unwrap_err().to_string();
    assert!(
        e.contains("gaussians.ply") && e.contains("after the 7 declared vertices"),
        "{e}"
    );
    // With a list element the size is only known after reading; checked at the end.
    let mut listed = xyz_ply(
        2,
        2,
        "element face 1\nproperty list uchar int vertex_indices\n",
    );
    let at = listed
        .windows(11)
        .position(|w| w == b"end_header\n")
        .unwrap()
        + 11;
    let face: Vec<u8> = [&[3u8][..], &[0; 12]].concat();
    listed.splice(at..at, face);
    let p = write_raw(d, "mesh.ply", &listed);
    assert_eq!(read_points(&p).unwrap().len(), 2);
    listed.extend_from_slice(&[0; 5]);
    let p = write_raw(d, "mesh-pad.ply", &listed);
    assert_eq!(read_points(&p).unwrap().len(), 2);
    listed.extend_from_slice(&[0; 12]);
    let p = write_raw(d, "mesh-extra.ply", &listed);
    let e = read_points(&p).unwrap_err().to_string();
    assert!(
        e.contains("mesh-extra.ply") && e.contains("17 bytes after the 2 declared vertices"),
        "{e}"
    );
    // Ascii: trailing blank lines and spaces are fine, more data is not.
    let head = "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nend_header\n";
    let p = write_raw(
        d,
        "a.ply",
        format!("{head}1 2 3\n4 5 6\n\n  \r\n").as_bytes(),
    );
    assert_eq!(read_points(&p).unwrap().positions, [1., 2., 3., 4., 5., 6.]);
    // Nor does an ascii file need a newline after its last value.
    let p = write_raw(d, "a-bare.ply", format!("{head}1 2 3\n4 5 6").as_bytes());
    assert_eq!(read_points(&p).unwrap().positions, [1., 2., 3., 4., 5., 6.]);
    let p = write_raw(
        d,
        "a-more.ply",
        format!("{head}1 2 3\n4 5 6\n7 8 9\n").as_bytes(),
    );
    let e = read_points(&p).unwrap_err().to_string();
    assert!(
        e.contains("a-more.ply") && e.contains("data after the 2 declared vertices"),
        "{e}"
    );
}

#[test]
fn truncated_plys_name_the_element_and_sizes() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let p = write_raw(d, "cut.ply", &xyz_ply(2189, 100, ""));
    let e = read_points(&p).unwrap_err().to_string();
    assert!(
        e.contains("cut.ply")
            && e.contains("element vertex")
            && e.contains("2189 declared vertices of 12 bytes need 26268 bytes")
            && e.contains("only 1200 remain (room for 100 whole)"),
        "{e}"
    );
    // An element before the vertex that runs out.
    let p = write_raw(
        d,
        "cut-junk.ply",
        &xyz_ply(1, 1, "element junk 100\nproperty uchar a\n"),
    );
    let e = read_points(&p).unwrap_err().to_string();
    assert!(
        e.contains("element junk") && e.contains("100 declared `junk` rows"),
        "{e}"
    );
    // Elements after the vertex are skipped to find the end of the data, so a property-less
    // one with a huge count must be refused before it becomes four billion loop turns.
    let mut after = xyz_ply(1, 1, "");
    let at = after
        .windows(11)
        .position(|w| w == b"end_header\n")
        .unwrap();
    after.splice(at..at, b"element junk 4000000000\n".iter().copied());
    let p = write_raw(d, "junk-after.ply", &after);
    let e = read_points(&p).unwrap_err().to_string();
    assert!(
        e.contains("element junk") && e.contains("cannot fit"),
        "{e}"
    );
    // A list element makes the size unknown until read: running out is still said plainly.
    let p = write_raw(
        d,
        "cut-list.ply",
        &xyz_ply(
            5,
            2,
            "element face 0\nproperty list uchar int vertex_indices\n",
        ),
    );
    let e = read_points(&p).unwrap_err().to_string();
    assert!(
        e.contains("cut-list.ply")
            && e.contains("element vertex")
            && e.contains("ends before the 5 declared vertices are read"),
        "{e}"
    );
    let p = write_raw(
        d,
        "cut.ascii.ply",
        b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nend_header\n1 2 3\n4 5 6\n",
    );
    let e = read_points(&p).unwrap_err().to_string();
    assert!(
        e.contains("cut.ascii.ply") && e.contains("ends before the 3 declared vertices"),
        "{e}"
    );
}

#[test]
fn the_last_format_line_decides_as_in_the_parser() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let xyz = "element vertex 1\nproperty float x\nproperty float y\nproperty float z\n";
    // Ascii after binary: an ascii body whose last value ends the file reads.
    let p = write_raw(
        d,
        "then-ascii.ply",
        format!("ply\nformat binary_little_endian 1.0\nformat ascii 1.0\n{xyz}end_header\n1 2 3")
            .as_bytes(),
    );
    assert_eq!(read_points(&p).unwrap().positions, [1.0, 2.0, 3.0]);
    // Binary after ascii, with nothing after `end_header`: no newline is lent to the header.
    let p = write_raw(
        d,
        "then-binary.ply",
        format!("ply\nformat ascii 1.0\nformat binary_little_endian 1.0\n{xyz}end_header")
            .as_bytes(),
    );
    let e = read_points(&p).unwrap_err().to_string();
    assert!(
        e.contains("then-binary.ply") && e.contains("`end_header` has no newline after it"),
        "{e}"
    );
}

#[test]
fn a_header_without_end_header_is_named() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let mut b = b"ply\nformat binary_little_endian 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\n".to_vec();
    b.extend_from_slice(&[0xff, 0xfe, 0x80, 0x81, 0x00, 0x01].repeat(10));
    let p = write_raw(d, "noend.ply", &b);
    let e = read_points(&p).unwrap_err().to_string();
    assert!(
        e.contains("noend.ply") && e.contains("no `end_header` line in the whole file"),
        "{e}"
    );
    // A header that has its end line but is otherwise bad keeps serde-ply's reason.
    let p = write_raw(
        d,
        "bad.ply",
        b"ply\nformat binary_little_endian 1.0\nelement vertex x\nend_header\n",
    );
    let e = read_points(&p).unwrap_err().to_string();
    assert!(
        e.contains("not a valid PLY header") && e.contains("count"),
        "{e}"
    );
}
