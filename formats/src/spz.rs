//! Niantic `.spz` (file version 3: one gzip stream), the compressed splat format Scaniverse,
//! SuperSplat, Spark, Babylon.js and three.js open. At SH 3 a Gaussian takes 65 bytes before
//! gzip, against the INRIA PLY's 248.
//!
//! Layout (all little-endian): a 16-byte header (magic "NGSP", version, count, SH degree,
//! fractional bits, flags, reserved), then per attribute an array over every splat: positions
//! as 24-bit fixed point, alpha, DC colour, log scale and SH as bytes, rotations as "smallest
//! three" (2-bit index of the largest component, three 10-bit signed magnitudes). Version 3 is
//! the newest every reader takes; version 4 (zstd streams) is not yet read by Babylon.js
//! without its WASM library.
//!
//! Frame: SPZ stores RUB axes (OpenGL's) and its library takes PLY as RDF (OpenCV's, as
//! COLMAP-trained scenes are), so the splats are turned 180° about X on the way in, exactly as
//! the library's own PLY conversion does, SH included; a reader that asks for RDF gets the
//! PLY's frame back.

use std::io::Write;
use std::path::Path;

use flate2::Compression;
use flate2::write::GzEncoder;

use crate::atomic::write_atomic;
use crate::error::{FormatError, Result};
use crate::splats::{Splats, sh_rest_per_channel, sigmoid};

const MAGIC: u32 = 0x5053_474e;
const VERSION: u32 = 3;
/// The library's choice: 2^-12 scene units, over ±2048 units.
const FRACTIONAL_BITS: u8 = 12;
const COLOR_SCALE: f32 = 0.15;
/// Bits kept per SH coefficient, degree 1 and above it (the library's defaults).
const SH1_BITS: u32 = 5;
const SH_REST_BITS: u32 = 4;

/// Writes `splats` to `path` as SPZ version 3 (through a temp file, renamed into place).
pub fn write_spz(path: &Path, splats: &Splats) -> Result<()> {
    splats.check_writable(path)?;
    let limit = f64::from((1u32 << 23) - 1) / f64::from(1u32 << FRACTIONAL_BITS);
    if let Some(i) = splats.means.iter().position(|x| f64::from(x.abs()) > limit) {
        return Err(FormatError::invalid(
            path,
            format!("splats.means[{i}]"),
            format!(
                "{} is outside SPZ's fixed-point range of ±{limit:.0} scene units (export as \
                 ply or glb, or rescale the scene)",
                splats.means[i]
            ),
        ));
    }
    let bytes = encode(splats);
    write_atomic(path, |w| {
        let mut gz = GzEncoder::new(w, Compression::default());
        gz.write_all(&bytes).map_err(|e| FormatError::io(path, e))?;
        gz.finish().map_err(|e| FormatError::io(path, e))?;
        Ok(())
    })
}

/// The uncompressed stream, in SPZ's RUB frame.
fn encode(s: &Splats) -> Vec<u8> {
    let n = s.len();
    let k = sh_rest_per_channel(s.sh_degree);
    let mut out = Vec::with_capacity(16 + n * (9 + 1 + 3 + 3 + 4 + 3 * k));
    out.extend(MAGIC.to_le_bytes());
    out.extend(VERSION.to_le_bytes());
    out.extend((n as u32).to_le_bytes());
    // Flags 0: cocog renders without the anti-aliasing filter's opacity compensation.
    out.extend([s.sh_degree as u8, FRACTIONAL_BITS, 0, 0]);
    let fixed = f64::from(1u32 << FRACTIONAL_BITS);
    for p in s.means.chunks_exact(3) {
        for v in rdf_to_rub(p) {
            let q = (f64::from(v) * fixed).round() as i32;
            out.extend(&q.to_le_bytes()[..3]);
        }
    }
    out.extend(s.opacities.iter().map(|&o| unit_byte(sigmoid(o) * 255.0)));
    out.extend(
        s.sh_dc
            .iter()
            .map(|&c| unit_byte(c * COLOR_SCALE * 255.0 + 127.5)),
    );
    out.extend(s.log_scales.iter().map(|&l| unit_byte((l + 10.0) * 16.0)));
    for q in s.rotations.chunks_exact(4) {
        out.extend(smallest_three(turn_rotation(q)).to_le_bytes());
    }
    for i in 0..n {
        for j in 0..k {
            let bits = if j < 3 { SH1_BITS } else { SH_REST_BITS };
            let sign = sh_sign(j);
            for c in 0..3 {
                out.push(sh_byte(sign * s.sh_rest[i * 3 * k + c * k + j], bits));
            }
        }
    }
    out
}

fn rdf_to_rub(p: &[f32]) -> [f32; 3] {
    [p[0], -p[1], -p[2]]
}

/// The unit quaternion, xyzw, of S·R(q)·S with S = diag(1, −1, −1) for q stored wxyz (a
/// zero one is the identity). S·R·Sᵀ and S·R give a Gaussian the same covariance in the turned
/// frame (S·D·S = D for its diagonal scales); this one is the library's conversion, so a
/// reader that asks for RDF gets q back exactly, not a quaternion of the same ellipsoid.
fn turn_rotation(q: &[f32]) -> [f32; 4] {
    let norm = q.iter().map(|v| v * v).sum::<f32>().sqrt();
    let [w, x, y, z] = if norm > 0.0 {
        [q[0], q[1], q[2], q[3]].map(|v| v / norm)
    } else {
        [1.0, 0.0, 0.0, 0.0]
    };
    [x, -y, -z, w]
}

/// The sign a 180° turn about X gives SH coefficient `j` (beyond DC) of degree l, order m:
/// y → −y flips the sin(|m|φ) terms (m < 0), z → −z contributes (−1)^(l+|m|).
fn sh_sign(j: usize) -> f32 {
    let l = ((j + 1) as f64).sqrt().floor() as i64;
    let m = j as i64 + 1 - l * l - l;
    let mut odd = (l + m.abs()) % 2 == 1;
    if m < 0 {
        odd = !odd;
    }
    if odd { -1.0 } else { 1.0 }
}

fn unit_byte(v: f32) -> u8 {
    v.round().clamp(0.0, 255.0) as u8
}

/// round(x·128) + 128 on a grid of 2^(8 − bits), as the library quantises.
fn sh_byte(x: f32, bits: u32) -> u8 {
    let bucket = 1i32 << (8 - bits);
    // Clamped before the cast: a huge coefficient must not saturate and overflow the sum.
    let q = ((x * 128.0).round() + 128.0).clamp(-1024.0, 1024.0) as i32;
    let q = (q + bucket / 2) / bucket * bucket;
    q.clamp(0, 255) as u8
}

/// "Smallest three": the largest component's index in the top 2 bits, the others (made
/// relative to a non-negative largest) as sign bit + 9-bit magnitude over 1/√2, x first.
fn smallest_three(q: [f32; 4]) -> u32 {
    let largest = (0..4)
        .max_by(|&a, &b| q[a].abs().total_cmp(&q[b].abs()))
        .expect("four components");
    let flip = q[largest] < 0.0;
    let mut packed = largest as u32;
    for (i, &v) in q.iter().enumerate() {
        if i == largest {
            continue;
        }
        let v = if flip { -v } else { v };
        let magnitude = (511.0 * v.abs() / std::f32::consts::FRAC_1_SQRT_2 + 0.5).floor();
        let magnitude = (magnitude as u32).min(511);
        packed = (packed << 10) | (u32::from(v < 0.0) << 9) | magnitude;
    }
    packed
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pose::rotation_from_wxyz;

    fn unpack(packed: u32) -> [f32; 4] {
        let largest = (packed >> 30) as usize;
        let mut q = [0.0f32; 4];
        let mut rest = packed;
        let mut sum = 0.0;
        for i in (0..4).rev() {
            if i == largest {
                continue;
            }
            let m = (rest & 511) as f32 / 511.0 * std::f32::consts::FRAC_1_SQRT_2;
            q[i] = if rest & 512 != 0 { -m } else { m };
            sum += q[i] * q[i];
            rest >>= 10;
        }
        q[largest] = (1.0 - sum).max(0.0).sqrt();
        q
    }

    #[test]
    fn smallest_three_round_trips_within_its_step() {
        for q in [
            [0.1f32, -0.7, 0.2, 0.67],
            [-0.9, 0.1, 0.3, -0.2],
            [0.5, 0.5, -0.5, 0.5],
            [0.0, 0.0, 0.0, 1.0],
        ] {
            let n = q.iter().map(|v| v * v).sum::<f32>().sqrt();
            let q = q.map(|v| v / n);
            let back = unpack(smallest_three(q));
            // The same rotation up to the quaternion's sign.
            let dot: f32 = q.iter().zip(&back).map(|(a, b)| a * b).sum();
            assert!(dot.abs() > 1.0 - 1e-5, "{q:?} -> {back:?}");
        }
    }

    #[test]
    fn the_turn_is_rx180_for_positions_rotations_and_sh() {
        let q = [0.9f32, 0.1, -0.3, 0.2];
        let t = turn_rotation(&q);
        let r0 = rotation_from_wxyz(q.map(f64::from));
        let r1 = rotation_from_wxyz([t[3], t[0], t[1], t[2]].map(f64::from));
        let flip = glam::DMat3::from_diagonal(glam::DVec3::new(1.0, -1.0, -1.0));
        assert!((flip * r0 * flip - r1).abs_diff_eq(glam::DMat3::ZERO, 1e-6));
        assert_eq!(rdf_to_rub(&[1.0, 2.0, 3.0]), [1.0, -2.0, -3.0]);
        // Degree 1 is (y, z, x): y and z flip. Degree 2: xy, yz, 3z²−1, xz, x²−y².
        let signs: Vec<f32> = (0..8).map(sh_sign).collect();
        assert_eq!(signs, [-1.0, -1.0, 1.0, -1.0, 1.0, 1.0, -1.0, 1.0]);
        // Degree 3: y(3x²−y²), xyz, y(5z²−1), z(5z²−3), x(5z²−1), z(x²−y²), x(x²−3y²).
        let signs: Vec<f32> = (8..15).map(sh_sign).collect();
        assert_eq!(signs, [-1.0, 1.0, -1.0, -1.0, 1.0, -1.0, 1.0]);
    }

    #[test]
    fn quantisers_follow_the_format() {
        assert_eq!(sh_byte(0.0, 5), 128);
        assert_eq!(sh_byte(1.5, 4), 255);
        assert_eq!(sh_byte(-2.0, 4), 0);
        assert_eq!(sh_byte(0.1, 5) % 8, 0);
        assert_eq!(sh_byte(3.0e9, 4), 255);
        assert_eq!(sh_byte(-3.0e9, 5), 0);
        assert_eq!(unit_byte(-3.0), 0);
        assert_eq!(unit_byte(300.0), 255);
    }

    #[test]
    fn bad_splats_are_refused_by_field() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("x.spz");
        let mut s = Splats::with_capacity(1, 0);
        s.means.extend([0.0, 5000.0, 0.0]);
        s.log_scales.extend([0.0; 3]);
        s.rotations.extend([1.0, 0.0, 0.0, 0.0]);
        s.opacities.push(0.0);
        s.sh_dc.extend([0.0; 3]);
        let e = write_spz(&path, &s).expect_err("out of range").to_string();
        assert!(
            e.contains("splats.means[1]") && e.contains("fixed-point"),
            "{e}"
        );
        // The range is ±(2^23 − 1)·2^-12: 2047.9 fits, 2048.1 does not.
        s.means[1] = -2047.9;
        write_spz(&path, &s).expect("inside the range");
        s.means[1] = 2048.1;
        write_spz(&path, &s).expect_err("just outside the range");
        std::fs::remove_file(&path).expect("remove");
        s.means[1] = f32::NAN;
        let e = write_spz(&path, &s).expect_err("NaN").to_string();
        assert!(e.contains("splats.means[1]"), "{e}");
        assert!(!path.exists());
    }
}
