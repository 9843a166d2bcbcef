//! INRIA adaptive density control: clone small Gaussians with large view-space gradients,
//! split large ones, prune faint ones. `plan_densify` is the rule on the CPU: the trainer's
//! fallback when a doubled set would not fit a buffer binding, and the oracle the GPU version
//! (densify_gpu.rs, the trainer's path) is tested against.

use cocog_engine::GaussianParams;

/// INRIA 2023 `OptimizationParams` densification defaults (method.md §7).
#[derive(Clone, Debug, PartialEq)]
pub struct DensifyConfig {
    /// Mean view-space (NDC) positional gradient norm at or above which a Gaussian densifies.
    pub grad_threshold: f32,
    /// Largest scale (× extent) up to which a Gaussian is cloned; above it, split.
    pub percent_dense: f32,
    pub min_opacity: f32,
    /// Densify at iterations in (from, until) divisible by `interval`; statistics are
    /// gathered at every iteration below `until`.
    pub from_iter: u32,
    pub until_iter: u32,
    pub interval: u32,
    /// Opacities are clamped to 0.01 every this many iterations (below `until_iter`); 0 never.
    pub opacity_reset_interval: u32,
    /// Gaussians whose largest scale exceeds this × the scene scale are pruned, from the
    /// first opacity reset on (INRIA: 0.1), or from the first densification when resets are
    /// off; 0 turns the rule off.
    pub prune_large: f32,
    /// Deblurring 3DGS's depth-weighted pruning (method.md §8.2): the opacity threshold is
    /// divided by a weight rising linearly from 1 at the nearest Gaussian to this at the
    /// farthest, so fewer far Gaussians are pruned; 1 is INRIA's uniform threshold.
    pub depth_prune_range: f32,
    /// Deblurring 3DGS's point addition (method.md §8.1) at this iteration; 0 never.
    pub add_points_at: u32,
    /// Candidates it draws: the train stage passes min(initial cloud's box volume / 1.1³,
    /// its `add_points_max` option), as the released code does.
    pub add_points_count: u32,
    /// A candidate with no Gaussian closer than this (scene units) is dropped.
    pub add_points_distance: f32,
}

/// What "depth" means for depth-weighted pruning: the distance along the cameras' mean
/// viewing direction (forward-facing captures, like Deblurring 3DGS's world z on LLFF data),
/// or from their centre when they look every way (a capture around an object).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DepthAxis {
    pub origin: [f64; 3],
    /// Unit mean forward direction, `None` when the cameras do not share one.
    pub forward: Option<[f64; 3]>,
}

impl DepthAxis {
    /// From camera centres and their forward directions (the third column of their
    /// rotations).
    pub fn from_cameras(centres: &[[f64; 3]], forwards: &[[f64; 3]]) -> Self {
        let n = centres.len().max(1) as f64;
        let mean = |v: &[[f64; 3]]| [0, 1, 2].map(|k| v.iter().map(|c| c[k]).sum::<f64>() / n);
        let f = mean(forwards);
        let len = (f[0] * f[0] + f[1] * f[1] + f[2] * f[2]).sqrt();
        // Half of the cameras' forward vectors cancel when they face around an object.
        Self {
            origin: mean(centres),
            forward: (len >= 0.5).then(|| f.map(|v| v / len)),
        }
    }

    pub fn depth(&self, p: [f32; 3]) -> f64 {
        let d = [0, 1, 2].map(|k| f64::from(p[k]) - self.origin[k]);
        match self.forward {
            Some(f) => d[0] * f[0] + d[1] * f[1] + d[2] * f[2],
            None => (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt(),
        }
    }
}

impl Default for DensifyConfig {
    fn default() -> Self {
        Self {
            grad_threshold: 2e-4,
            percent_dense: 0.01,
            min_opacity: 0.005,
            from_iter: 500,
            until_iter: 15_000,
            interval: 100,
            opacity_reset_interval: 3000,
            prune_large: 0.1,
            depth_prune_range: 1.0,
            add_points_at: 0,
            add_points_count: 200_000,
            add_points_distance: 2.0,
        }
    }
}

impl DensifyConfig {
    /// cocog's default: INRIA's rules without the world-space large-Gaussian prune. On a
    /// forward-facing capture the camera extent it is relative to is a few centimetres while
    /// the scene is metres deep, so it deletes the background at every densification after the
    /// first opacity reset. Measured on sharp-dev (H100, BENCHMARKS.md): 24.0 dB test PSNR
    /// with it, 39.3 dB without it at 30000 iterations; scaling the rules by the depth instead
    /// lost 0.9 dB, and dropping the opacity resets lost 4.9 dB (100×75, 7000 iterations).
    pub fn auto() -> Self {
        Self {
            prune_large: 0.0,
            ..Self::default()
        }
    }

    /// CoCoGaussian's (and Deblurring 3DGS's) policy, from the released code: densify until
    /// 20000, no opacity reset, no large-Gaussian prune, depth-weighted pruning over a range
    /// of 3, the point addition at 2500. Kept for fidelity: on the tiny thin-lens test scene
    /// (`gpu_coc_train.rs`) runs with it ended at 18.9–21.3 dB and one without it at 20.0 dB,
    /// which decides nothing.
    pub fn deblur() -> Self {
        Self {
            until_iter: 20_000,
            opacity_reset_interval: 0,
            prune_large: 0.0,
            depth_prune_range: 3.0,
            add_points_at: 2500,
            ..Self::default()
        }
    }

    pub fn densifies_at(&self, it: u32) -> bool {
        it < self.until_iter && it > self.from_iter && it.is_multiple_of(self.interval.max(1))
    }

    pub fn adds_points_at(&self, it: u32) -> bool {
        self.add_points_at > 0 && it == self.add_points_at
    }

    pub fn resets_opacity_at(&self, it: u32) -> bool {
        self.opacity_reset_interval > 0
            && it < self.until_iter
            && it.is_multiple_of(self.opacity_reset_interval)
    }

    /// Whether densifying at `it` also prunes large Gaussians: INRIA passes its size
    /// threshold once iteration `opacity_reset_interval` is past.
    pub fn prunes_large_at(&self, it: u32) -> bool {
        self.prune_large > 0.0 && it > self.opacity_reset_interval
    }
}

/// Where one Gaussian of the densified set comes from.
#[derive(Clone, Debug, PartialEq)]
pub enum Origin {
    Keep(usize),
    Clone(usize),
    /// A split child: the parent's parameters with a sampled mean and the scale / 1.6.
    Split {
        parent: usize,
        mean: [f32; 3],
        log_scale: [f32; 3],
    },
}

impl Origin {
    fn source(&self) -> usize {
        match *self {
            Origin::Keep(i) | Origin::Clone(i) => i,
            Origin::Split { parent, .. } => parent,
        }
    }
}

/// The densified set, in INRIA order: surviving originals, clones, split children.
#[derive(Clone, Debug, PartialEq)]
pub struct DensifyPlan {
    pub origins: Vec<Origin>,
    pub cloned: usize,
    pub split: usize,
    pub pruned: usize,
}

/// Split children per parent, and the scale divisor 0.8 · N of INRIA.
const SPLIT_CHILDREN: usize = 2;
const SPLIT_SCALE_DIV: f32 = 0.8 * SPLIT_CHILDREN as f32;

/// INRIA `densify_and_prune` with world-space rules relative to `scale` (INRIA: the camera
/// extent). `prune_large` is INRIA's `max_screen_size` branch (`DensifyConfig::prunes_large_at`);
/// only its world-space test is modelled, because INRIA zeroes `max_radii2D` in
/// `densification_postfix` just before it, so its screen-size test never fires. With
/// `depth_prune_range` > 1, depths along `axis` weight the opacity threshold. Split children
/// are sampled from `noise`, as densify.wgsl samples them.
pub fn plan_densify(
    g: &GaussianParams,
    mean_grads: &[f32],
    scale: f64,
    prune_large: bool,
    config: &DensifyConfig,
    noise: &SplitNoise,
    axis: Option<&DepthAxis>,
) -> DensifyPlan {
    let n = g.len();
    let dense = (f64::from(config.percent_dense) * scale) as f32;
    let max_scale = |l: &[f32; 3]| l.iter().fold(f32::MIN, |m, &v| m.max(v.exp()));
    let hot = |i: usize| {
        mean_grads
            .get(i)
            .is_some_and(|&v| v >= config.grad_threshold)
    };
    let clones: Vec<usize> = (0..n)
        .filter(|&i| hot(i) && max_scale(&g.log_scales[i]) <= dense)
        .collect();
    let splits: Vec<usize> = (0..n)
        .filter(|&i| hot(i) && max_scale(&g.log_scales[i]) > dense)
        .collect();
    let mut origins: Vec<Origin> = (0..n)
        .filter(|i| splits.binary_search(i).is_err())
        .map(Origin::Keep)
        .collect();
    origins.extend(clones.iter().map(|&i| Origin::Clone(i)));
    // torch's `repeat(N, 1)`: all first children, then all second children.
    for child in 0..SPLIT_CHILDREN {
        for &i in &splits {
            let scale = g.log_scales[i].map(f32::exp);
            let sample: [f64; 3] =
                std::array::from_fn(|a| f64::from(scale[a]) * noise.normal(i, child, a));
            let r = rotation(g.quats[i]);
            let mean = std::array::from_fn(|row| {
                let offset: f64 = (0..3).map(|c| r[row][c] * sample[c]).sum();
                (f64::from(g.means[i][row]) + offset) as f32
            });
            let log_scale = scale.map(|s| (s / SPLIT_SCALE_DIV).ln());
            origins.push(Origin::Split {
                parent: i,
                mean,
                log_scale,
            });
        }
    }
    let before = origins.len();
    let large = (f64::from(config.prune_large) * scale) as f32;
    let mean_of = |o: &Origin| match o {
        Origin::Split { mean, .. } => *mean,
        _ => g.means[o.source()],
    };
    // Deblurring 3DGS: threshold / (1 + (range − 1)·(z − z_min)/(z_max − z_min)) over the
    // Gaussians after cloning and splitting.
    let range = f64::from(config.depth_prune_range);
    let threshold: Vec<f32> = match axis.filter(|_| range > 1.0) {
        Some(axis) => {
            let z: Vec<f64> = origins.iter().map(|o| axis.depth(mean_of(o))).collect();
            let lo = z.iter().copied().fold(f64::INFINITY, f64::min);
            let hi = z.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            let span = (hi - lo).max(f64::MIN_POSITIVE);
            z.iter()
                .map(|z| {
                    (f64::from(config.min_opacity) / (1.0 + (range - 1.0) * (z - lo) / span)) as f32
                })
                .collect()
        }
        None => vec![config.min_opacity; origins.len()],
    };
    let mut keep = threshold.iter();
    origins.retain(|o| {
        let opacity = sigmoid(g.opacity_logits[o.source()]);
        let log_scale = match o {
            Origin::Split { log_scale, .. } => log_scale,
            _ => &g.log_scales[o.source()],
        };
        let t = keep.next().copied().unwrap_or(config.min_opacity);
        !(opacity < t || (prune_large && max_scale(log_scale) > large))
    });
    DensifyPlan {
        pruned: before - origins.len(),
        cloned: clones.len(),
        split: splits.len(),
        origins,
    }
}

/// Rows of a per-Gaussian buffer of `stride` floats, rearranged by `origins`. New Gaussians
/// copy their source row, or get zeros when `new_zero` (INRIA starts their Adam moments at 0).
pub fn gather_rows(data: &[f32], stride: usize, origins: &[Origin], new_zero: bool) -> Vec<f32> {
    let mut out = Vec::with_capacity(origins.len() * stride);
    for o in origins {
        let row = &data[o.source() * stride..(o.source() + 1) * stride];
        match o {
            Origin::Keep(_) => out.extend_from_slice(row),
            _ if new_zero => out.extend(std::iter::repeat_n(0.0, stride)),
            _ => out.extend_from_slice(row),
        }
    }
    out
}

/// The densified Gaussians.
pub fn apply_plan(g: &GaussianParams, plan: &DensifyPlan) -> GaussianParams {
    let o = &plan.origins;
    let rows3 = |v: &[[f32; 3]]| -> Vec<[f32; 3]> { o.iter().map(|x| v[x.source()]).collect() };
    let mut means = rows3(&g.means);
    let mut log_scales = rows3(&g.log_scales);
    for (k, x) in o.iter().enumerate() {
        if let Origin::Split {
            mean, log_scale, ..
        } = x
        {
            means[k] = *mean;
            log_scales[k] = *log_scale;
        }
    }
    GaussianParams {
        sh_degree: g.sh_degree,
        means,
        log_scales,
        quats: o.iter().map(|x| g.quats[x.source()]).collect(),
        opacity_logits: o.iter().map(|x| g.opacity_logits[x.source()]).collect(),
        sh: gather_rows(&g.sh, g.sh_stride(), o, false),
    }
}

fn sigmoid(x: f32) -> f32 {
    1.0 / (1.0 + (-x).exp())
}

/// The standard normals split children are drawn with: a counter-based hash of the seed, the
/// iteration, the Gaussian, the child and the axis, so the GPU (densify.wgsl) draws the same
/// ones in any order and a resumed run draws what the uninterrupted one did.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SplitNoise {
    pub seed: u64,
    pub iteration: u32,
}

impl SplitNoise {
    /// Box–Muller on two 24-bit uniforms, u1 in (0, 1] and u2 in [0, 1).
    pub fn normal(&self, gaussian: usize, child: usize, axis: usize) -> f64 {
        let key = pcg(self.seed as u32
            ^ pcg((self.seed >> 32) as u32
                ^ pcg(self.iteration ^ pcg(gaussian as u32 ^ pcg(child as u32 * 3 + axis as u32)))));
        let unit = 1.0 / f64::from(1u32 << 24);
        let u1 = f64::from((pcg(key ^ 1) >> 8) + 1) * unit;
        let u2 = f64::from(pcg(key ^ 2) >> 8) * unit;
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }
}

/// PCG hash (Jarzynski & Olano, "Hash functions for GPU rendering", 2020).
fn pcg(v: u32) -> u32 {
    let state = v.wrapping_mul(747_796_405).wrapping_add(2_891_336_453);
    let word = ((state >> ((state >> 28) + 4)) ^ state).wrapping_mul(277_803_737);
    (word >> 22) ^ word
}

/// INRIA `build_rotation` of a (w, x, y, z) quaternion, normalised first.
fn rotation(q: [f32; 4]) -> [[f64; 3]; 3] {
    let q = q.map(f64::from);
    let len = q.iter().map(|v| v * v).sum::<f64>().sqrt().max(1e-12);
    cocog_engine::reference::quat_to_rot(q.map(|v| v / len))
}
