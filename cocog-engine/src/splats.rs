//! Conversions between the PLY-shaped `Splats` of cocog-formats and the engine's parameters.
//!
//! Both hold the INRIA pre-activation values; only the SH layout differs: the PLY keeps DC and
//! the higher bands in separate arrays, the engine one channel-major block per Gaussian so a
//! kernel reads a Gaussian's colour from one place.

use cocog_formats::splats::Splats;

use crate::types::{GaussianParams, sh_coeffs_per_channel};

fn triples(v: &[f32]) -> Vec<[f32; 3]> {
    v.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect()
}

impl From<&Splats> for GaussianParams {
    fn from(s: &Splats) -> Self {
        let rest = s.rest_per_channel();
        let k = sh_coeffs_per_channel(s.sh_degree);
        let mut sh = Vec::with_capacity(s.len() * 3 * k);
        for i in 0..s.len() {
            for c in 0..3 {
                sh.push(s.sh_dc[3 * i + c]);
                let start = i * 3 * rest + c * rest;
                sh.extend_from_slice(&s.sh_rest[start..start + rest]);
            }
        }
        Self {
            sh_degree: s.sh_degree,
            means: triples(&s.means),
            log_scales: triples(&s.log_scales),
            quats: s
                .rotations
                .chunks_exact(4)
                .map(|q| [q[0], q[1], q[2], q[3]])
                .collect(),
            opacity_logits: s.opacities.clone(),
            sh,
        }
    }
}

impl From<&GaussianParams> for Splats {
    fn from(g: &GaussianParams) -> Self {
        let k = sh_coeffs_per_channel(g.sh_degree);
        let mut s = Splats::with_capacity(g.len(), g.sh_degree);
        for i in 0..g.len() {
            s.means.extend(g.means[i]);
            s.log_scales.extend(g.log_scales[i]);
            s.rotations.extend(g.quats[i]);
            s.opacities.push(g.opacity_logits[i]);
            let sh = &g.sh[i * 3 * k..(i + 1) * 3 * k];
            s.sh_dc.extend((0..3).map(|c| sh[c * k]));
            for c in 0..3 {
                s.sh_rest.extend_from_slice(&sh[c * k + 1..(c + 1) * k]);
            }
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_keeps_every_value_and_maps_the_sh_layout() {
        // Two splats of degree 1: 3 rest coefficients per channel.
        let s = Splats {
            means: (0..6).map(|v| v as f32).collect(),
            log_scales: (10..16).map(|v| v as f32).collect(),
            rotations: (20..28).map(|v| v as f32).collect(),
            opacities: vec![0.5, -0.5],
            sh_dc: vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0],
            sh_rest: (100..118).map(|v| v as f32).collect(),
            sh_degree: 1,
        };
        let g = GaussianParams::from(&s);
        g.validate().unwrap();
        // Splat 1, channel 2 (blue): DC 6.0, then f_rest_6..8 of that splat.
        assert_eq!(&g.sh[12 + 8..12 + 12], &[6.0, 115.0, 116.0, 117.0]);
        assert_eq!(g.quats[1], [24.0, 25.0, 26.0, 27.0]);
        assert_eq!(Splats::from(&g), s);
    }
}
