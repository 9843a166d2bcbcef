//! Gaussian splats in INRIA 3DGS parameterisation, structure-of-arrays of f32 for GPU upload.

/// Coefficients per colour channel beyond DC for SH degree `d`: (d+1)² − 1.
pub const fn sh_rest_per_channel(degree: u32) -> usize {
    ((degree + 1) * (degree + 1) - 1) as usize
}

/// Gaussians as the INRIA PLY stores them (pre-activation values).
///
/// Every vector is flat: splat `i` owns `means[3i..3i+3]`, `rotations[4i..4i+4]` and so on.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Splats {
    /// World positions.
    pub means: Vec<f32>,
    /// Natural log of the standard deviation along each local axis.
    pub log_scales: Vec<f32>,
    /// Quaternions w, x, y, z; not necessarily normalised (INRIA saves the raw parameter).
    pub rotations: Vec<f32>,
    /// Opacity logits: α = sigmoid(v).
    pub opacities: Vec<f32>,
    /// DC SH coefficients R, G, B.
    pub sh_dc: Vec<f32>,
    /// Higher SH coefficients, per splat channel-major: `sh_rest[i*3K + c*K + j]`, K = `sh_rest_per_channel(sh_degree)`.
    pub sh_rest: Vec<f32>,
    /// 0 to 3.
    pub sh_degree: u32,
}

impl Splats {
    /// An empty set with room for `n` splats.
    pub fn with_capacity(n: usize, sh_degree: u32) -> Self {
        let k = sh_rest_per_channel(sh_degree);
        Splats {
            means: Vec::with_capacity(3 * n),
            log_scales: Vec::with_capacity(3 * n),
            rotations: Vec::with_capacity(4 * n),
            opacities: Vec::with_capacity(n),
            sh_dc: Vec::with_capacity(3 * n),
            sh_rest: Vec::with_capacity(3 * k * n),
            sh_degree,
        }
    }

    pub fn len(&self) -> usize {
        self.opacities.len()
    }

    pub fn is_empty(&self) -> bool {
        self.opacities.is_empty()
    }

    /// SH coefficients per channel beyond DC.
    pub fn rest_per_channel(&self) -> usize {
        sh_rest_per_channel(self.sh_degree)
    }

    /// Keeps the splats whose `keep` entry is true, in order.
    ///
    /// # Panics
    /// If `keep` does not hold one entry per splat: a mask made for other splats.
    pub fn retain(&mut self, keep: &[bool]) {
        assert_eq!(
            keep.len(),
            self.len(),
            "Splats::retain: a mask of {} for {} splats",
            keep.len(),
            self.len()
        );
        fn filter(v: &mut Vec<f32>, width: usize, keep: &[bool]) {
            let mut out = 0;
            for (i, k) in keep.iter().enumerate() {
                if *k {
                    v.copy_within(i * width..(i + 1) * width, out * width);
                    out += 1;
                }
            }
            v.truncate(out * width);
        }
        let k3 = 3 * self.rest_per_channel();
        filter(&mut self.means, 3, keep);
        filter(&mut self.log_scales, 3, keep);
        filter(&mut self.rotations, 4, keep);
        filter(&mut self.opacities, 1, keep);
        filter(&mut self.sh_dc, 3, keep);
        if k3 > 0 {
            filter(&mut self.sh_rest, k3, keep);
        }
    }

    /// Whether each splat is one every writer and reader accepts: all values finite, and a
    /// rotation that is not all zero.
    pub fn writable_mask(&self) -> Vec<bool> {
        let k3 = 3 * self.rest_per_channel();
        let ok = |v: &[f32]| v.iter().all(|x| x.is_finite());
        (0..self.len())
            .map(|i| {
                ok(&self.means[3 * i..3 * i + 3])
                    && ok(&self.log_scales[3 * i..3 * i + 3])
                    && ok(&self.rotations[4 * i..4 * i + 4])
                    && self.rotations[4 * i..4 * i + 4].iter().any(|&q| q != 0.0)
                    && self.opacities[i].is_finite()
                    && ok(&self.sh_dc[3 * i..3 * i + 3])
                    && ok(&self.sh_rest[k3 * i..k3 * (i + 1)])
            })
            .collect()
    }

    /// The first NaN or infinite value as (field, flat index), for writers whose format
    /// cannot hold one.
    pub fn first_non_finite(&self) -> Option<(&'static str, usize)> {
        [
            ("means", &self.means),
            ("log_scales", &self.log_scales),
            ("rotations", &self.rotations),
            ("opacities", &self.opacities),
            ("sh_dc", &self.sh_dc),
            ("sh_rest", &self.sh_rest),
        ]
        .into_iter()
        .find_map(|(name, v)| v.iter().position(|x| !x.is_finite()).map(|i| (name, i)))
    }

    /// What every writer checks first: consistent lengths, and no NaN or infinity, which no
    /// reader (this crate's, or a viewer's) accepts.
    pub(crate) fn check_writable(&self, path: &std::path::Path) -> crate::error::Result<()> {
        use crate::error::FormatError;
        self.check()
            .map_err(|e| FormatError::invalid(path, "splats", e))?;
        if let Some((name, i)) = self.first_non_finite() {
            return Err(FormatError::invalid(
                path,
                format!("splats.{name}[{i}]"),
                "is NaN or infinite",
            ));
        }
        Ok(())
    }

    /// Checks that every vector has the length `len()` implies, or says which one does not.
    pub fn check(&self) -> Result<(), String> {
        if self.sh_degree > 3 {
            return Err(format!("sh_degree {} is above 3", self.sh_degree));
        }
        let n = self.len();
        let k = self.rest_per_channel();
        for (name, len, per) in [
            ("means", self.means.len(), 3),
            ("log_scales", self.log_scales.len(), 3),
            ("rotations", self.rotations.len(), 4),
            ("sh_dc", self.sh_dc.len(), 3),
            ("sh_rest", self.sh_rest.len(), 3 * k),
        ] {
            if len != n * per {
                return Err(format!(
                    "{name} has {len} values, expected {} for {n} splats",
                    n * per
                ));
            }
        }
        Ok(())
    }
}

/// The SH DC constant Y₀₀ = 1 / (2√π).
pub const SH_C0: f32 = 0.282_094_8;

/// DC coefficient of a colour in [0, 1]: inverse of `0.5 + C0 · dc`.
pub fn rgb_to_sh_dc(rgb: f32) -> f32 {
    (rgb - 0.5) / SH_C0
}

/// Logit, the inverse of the sigmoid that maps opacity parameters to α.
pub fn logit(alpha: f32) -> f32 {
    (alpha / (1.0 - alpha)).ln()
}

pub fn sigmoid(v: f32) -> f32 {
    1.0 / (1.0 + (-v).exp())
}
