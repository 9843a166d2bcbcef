//! The f64 reference of h_θ and the CoC expansion against central finite differences, per
//! scalar: every weight and bias of every layer, every head of both variants, the base
//! parameters through all M + 1 sets, and the focus distance through the gate.

mod common;

use cocog_engine::coc::reference::{
    Base, Expanded, expand, expand_backward, gate, input, mlp_backward, mlp_forward, multiplier,
    variant_gate,
};
use cocog_engine::coc::{CocConfig, CocVariant, HeadLayout, MlpLayout, init_weights};
use common::Rng;

const STEP: f64 = 1e-6;
/// The frame's scale D: not 1, so the code variant's division by it is differentiated too.
const SCALE: f64 = 0.7;

/// A loss that weighs every output of every set differently, so no gradient hides in a sum.
struct Probe {
    coef: Vec<Expanded>,
}

impl Probe {
    fn new(sets: usize, rng: &mut Rng) -> Self {
        let mut r = || rng.range(-1.0, 1.0);
        let coef = (0..sets)
            .map(|_| Expanded {
                mean: [r(), r(), r()],
                log_scale: [r(), r(), r()],
                quat: [r(), r(), r(), r()],
            })
            .collect();
        Self { coef }
    }

    fn loss(&self, sets: &[Expanded]) -> f64 {
        let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
        sets.iter()
            .zip(&self.coef)
            .map(|(s, c)| {
                dot(&s.mean, &c.mean) + dot(&s.log_scale, &c.log_scale) + dot(&s.quat, &c.quat)
            })
            .sum()
    }
}

struct Case {
    config: CocConfig,
    hl: HeadLayout,
    ml: MlpLayout,
    weights: Vec<f64>,
    base: Base,
    camera: [f64; 3],
    focus: f64,
    /// The lens variant's per-photo aperture a (K = a·d).
    aperture: f64,
    probe: Probe,
}

impl Case {
    fn new(variant: CocVariant, centred: bool, seed: u64) -> Self {
        let mut config = CocConfig::new(variant);
        config.width = 8;
        config.centred = centred;
        // The released code modulates the base set; the centred cases check the other way.
        config.modulate_base = !centred;
        let (hl, ml) = (config.heads(), config.mlp());
        let mut weights: Vec<f64> = init_weights(&ml, seed)
            .iter()
            .map(|&v| f64::from(v))
            .collect();
        // Larger head weights spread the heads over the multiplier's clamped and open ranges.
        let (_, fan_out, wo, bo) = ml.layers[3];
        for v in &mut weights[wo..bo + fan_out] {
            *v *= 3.0;
        }
        let mut rng = Rng::new(seed + 1);
        let base = Base {
            mean: [
                rng.range(-0.3, 0.3),
                rng.range(-0.3, 0.3),
                rng.range(0.8, 1.2),
            ],
            log_scale: [
                rng.range(-3.0, -1.0),
                rng.range(-3.0, -1.0),
                rng.range(-3.0, -1.0),
            ],
            quat: [
                rng.range(0.5, 1.5),
                rng.range(-0.5, 0.5),
                rng.range(-0.5, 0.5),
                rng.range(-0.5, 0.5),
            ],
        };
        Self {
            config,
            hl,
            ml,
            weights,
            base,
            camera: [0.05, -0.02, -0.1],
            focus: 2.3,
            aperture: 1.2,
            probe: Probe::new(hl.copies + 1, &mut rng),
        }
    }

    fn heads(&self, weights: &[f64]) -> Vec<f64> {
        mlp_forward(&self.ml, weights, input(&self.base, self.camera)).heads
    }

    /// The base's distance from the camera (detached, like the gate's).
    fn depth(&self) -> f64 {
        (0..3)
            .map(|k| (self.base.mean[k] - self.camera[k]).powi(2))
            .sum::<f64>()
            .sqrt()
    }

    /// The gate the variant uses, and its derivative with respect to the focus distance.
    fn gate(&self, focus: f64) -> (f64, f64) {
        let g = gate(self.base.mean, self.camera, focus);
        variant_gate(self.config.variant, g, SCALE)
    }

    fn loss_with(&self, base: &Base, heads: &[f64], focus: f64, aperture: f64) -> f64 {
        let (c, _) = self.gate(focus);
        let k = aperture * self.depth();
        self.probe
            .loss(&expand(&self.config, base, heads, (c, k, SCALE)))
    }

    fn loss(&self, base: &Base, heads: &[f64], focus: f64) -> f64 {
        self.loss_with(base, heads, focus, self.aperture)
    }

    /// Every analytic gradient: weights, heads, base (as one Expanded), focus, aperture.
    fn analytic(&self) -> (Vec<f64>, Vec<f64>, Expanded, f64, f64) {
        let trace = mlp_forward(&self.ml, &self.weights, input(&self.base, self.camera));
        let (c, dc_dfocus) = self.gate(self.focus);
        let g = expand_backward(
            &self.config,
            &self.base,
            &trace.heads,
            (c, self.aperture * self.depth(), SCALE),
            &self.probe.coef,
        );
        let mut v_weights = vec![0.0; self.ml.len];
        mlp_backward(&self.ml, &self.weights, &trace, &g.v_heads, &mut v_weights);
        let v_aperture = g.v_lens_k * self.depth();
        (
            v_weights,
            g.v_heads,
            g.base,
            g.v_gate * dc_dfocus,
            v_aperture,
        )
    }
}

fn central(f: impl Fn(f64) -> f64, x: f64) -> f64 {
    (f(x + STEP) - f(x - STEP)) / (2.0 * STEP)
}

fn check(what: &str, analytic: f64, fd: f64) {
    let tol = 1e-6 + 1e-5 * fd.abs();
    assert!(
        (analytic - fd).abs() <= tol,
        "{what}: analytic {analytic:e} vs finite difference {fd:e}"
    );
}

/// The case must exercise both the open and the clamped ranges of the multipliers, with no head
/// so close to a clamp edge that a finite-difference step crosses it.
fn assert_well_posed(case: &Case) {
    let heads = case.heads(&case.weights);
    let (c, _) = case.gate(case.focus);
    let (e, top) = (std::f64::consts::E, 1.1f64.exp());
    let (mut open, mut clamped) = (0, 0);
    for &h in &heads[case.hl.scale..case.hl.len] {
        let x = c * h + e - 0.01;
        assert!(
            (x - e).abs() > 1e-4 && (x - top).abs() > 1e-4,
            "head {h} sits on a clamp edge"
        );
        if multiplier(c, h).1 > 0.0 {
            open += 1
        } else {
            clamped += 1
        }
    }
    assert!(open >= 4 && clamped >= 4, "open {open}, clamped {clamped}");
}

fn field<'a>(b: &'a mut Base, name: &str, k: usize) -> &'a mut f64 {
    match name {
        "mean" => &mut b.mean[k],
        "log_scale" => &mut b.log_scale[k],
        _ => &mut b.quat[k],
    }
}

fn run(variant: CocVariant, centred: bool, seed: u64) {
    let case = Case::new(variant, centred, seed);
    assert_well_posed(&case);
    let heads = case.heads(&case.weights);
    let (v_weights, v_heads, v_base, v_focus, v_aperture) = case.analytic();

    for i in 0..case.ml.len {
        let fd = central(
            |x| {
                let mut w = case.weights.clone();
                w[i] = x;
                case.loss(&case.base, &case.heads(&w), case.focus)
            },
            case.weights[i],
        );
        check(&format!("{} weight {i}", variant.name()), v_weights[i], fd);
    }
    for i in 0..case.hl.len {
        let fd = central(
            |x| {
                let mut h = heads.clone();
                h[i] = x;
                case.loss(&case.base, &h, case.focus)
            },
            heads[i],
        );
        check(&format!("{} head {i}", variant.name()), v_heads[i], fd);
    }
    // The base enters the sets directly; h_θ's input and the gate see it detached.
    let fields: [(&str, usize); 3] = [("mean", 3), ("log_scale", 3), ("quat", 4)];
    for (name, len) in fields {
        for k in 0..len {
            let fd = central(
                |x| {
                    let mut b = case.base;
                    *field(&mut b, name, k) = x;
                    case.loss(&b, &heads, case.focus)
                },
                *field(&mut case.base.clone(), name, k),
            );
            let mut v = Base {
                mean: v_base.mean,
                log_scale: v_base.log_scale,
                quat: v_base.quat,
            };
            let analytic = *field(&mut v, name, k);
            check(
                &format!("{} base {name}[{k}]", variant.name()),
                analytic,
                fd,
            );
        }
    }
    let fd = central(
        |a| case.loss_with(&case.base, &heads, case.focus, a),
        case.aperture,
    );
    check(&format!("{} aperture", variant.name()), v_aperture, fd);
    if variant == CocVariant::Lens {
        assert!(
            v_aperture.abs() > 1e-3,
            "the aperture gradient must be exercised"
        );
    }
    let fd = central(|f| case.loss(&case.base, &heads, f), case.focus);
    check(&format!("{} focus distance", variant.name()), v_focus, fd);
    assert!(
        v_focus.abs() > 1e-3,
        "the focus gradient must be exercised: {v_focus}"
    );
}

#[test]
fn code_variant_matches_finite_differences() {
    run(CocVariant::Code, false, 11);
    run(CocVariant::Code, true, 12);
}

#[test]
fn paper_variant_matches_finite_differences() {
    run(CocVariant::Paper, false, 23);
    run(CocVariant::Paper, true, 24);
}

#[test]
fn lens_variant_matches_finite_differences() {
    run(CocVariant::Lens, false, 31);
    run(CocVariant::Lens, true, 32);
}

/// Centred copies average to the base: the circle of confusion sits on the in-focus point.
#[test]
fn centred_copies_average_to_the_base() {
    for variant in [CocVariant::Code, CocVariant::Paper, CocVariant::Lens] {
        let case = Case::new(variant, true, 6);
        let (c, _) = case.gate(case.focus);
        assert!(c > 0.1, "the gate must be open: {c}");
        let sets = expand(
            &case.config,
            &case.base,
            &case.heads(&case.weights),
            (c, case.aperture * case.depth(), SCALE),
        );
        let copies = &sets[..case.hl.copies];
        for k in 0..3 {
            let mean = copies.iter().map(|s| s.mean[k]).sum::<f64>() / copies.len() as f64;
            assert!((mean - case.base.mean[k]).abs() < 1e-12, "axis {k}: {mean}");
            let spread = copies.iter().map(|s| (s.mean[k] - mean).abs()).sum::<f64>();
            assert!(spread > 1e-4, "the copies must still spread: {spread}");
        }
    }
}

/// In focus (d = d_F) the gate closes: copies coincide with the base, nothing is modulated.
#[test]
fn in_focus_gaussians_do_not_spread() {
    for variant in [CocVariant::Code, CocVariant::Paper, CocVariant::Lens] {
        let case = Case::new(variant, false, 5);
        let d = (0..3)
            .map(|k| (case.base.mean[k] - case.camera[k]).powi(2))
            .sum::<f64>()
            .sqrt();
        let (c, _) = case.gate(d);
        assert!(c < 1e-12);
        let sets = expand(
            &case.config,
            &case.base,
            &case.heads(&case.weights),
            (c, case.aperture * case.depth(), SCALE),
        );
        let n = case.base.quat.iter().map(|v| v * v).sum::<f64>().sqrt();
        for s in sets {
            for k in 0..3 {
                assert!((s.mean[k] - case.base.mean[k]).abs() < 1e-9);
                assert!((s.log_scale[k] - case.base.log_scale[k]).abs() < 1e-12);
            }
            for k in 0..4 {
                assert!((s.quat[k] - case.base.quat[k] / n).abs() < 1e-12);
            }
        }
    }
}

/// The code variant spreads its copies as the released code does in the scene's own units:
/// c·raw with c = |1/d − 1/d_F| in those units, whatever frame the GPU computes in. Heads
/// are held fixed (h_θ's inputs are the frame's, so its heads would differ).
#[test]
fn the_code_variants_offsets_are_in_scene_units_in_any_frame() {
    let config = CocConfig::new(CocVariant::Code);
    let hl = config.heads();
    let mut rng = Rng::new(77);
    let heads: Vec<f64> = (0..hl.len).map(|_| rng.range(-1.0, 1.0)).collect();
    let (mean, camera, focus): ([f64; 3], [f64; 3], f64) =
        ([0.2, -0.1, 1.9], [0.05, -0.02, -0.1], 0.9);
    let d = (0..3)
        .map(|k| (mean[k] - camera[k]).powi(2))
        .sum::<f64>()
        .sqrt();
    let c_scene = (1.0 / d - 1.0 / focus).abs();
    for scale in [0.25, 1.0, 3.0] {
        let frame = |p: [f64; 3]| p.map(|v| v / scale);
        let base = Base {
            mean: frame(mean),
            log_scale: [-3.0; 3],
            quat: [1.0, 0.0, 0.0, 0.0],
        };
        let g = gate(base.mean, frame(camera), focus / scale);
        let (c, _) = variant_gate(CocVariant::Code, g, scale);
        let sets = expand(&config, &base, &heads, (c, 0.0, scale));
        for (m, set) in sets[..hl.copies].iter().enumerate() {
            for k in 0..3 {
                let offset = (set.mean[k] - base.mean[k]) * scale;
                let want = c_scene * heads[hl.pos + 3 * m + k];
                assert!(
                    (offset - want).abs() < 1e-12 * (1.0 + want.abs()),
                    "scale {scale}, copy {m}, axis {k}: offset {offset} against {want}"
                );
            }
        }
    }
}
