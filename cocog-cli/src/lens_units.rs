//! How long a scene unit is in the truth's metres, read from the cameras both place.
//!
//! A COLMAP model's units are arbitrary and `cocog recenter` rescales a scene, so a learned
//! focus distance cannot be compared with a dataset's `focus_distance_m` as it stands. Camera
//! centres are the one thing both sides locate: the distance between two photos' centres in
//! metres over the same distance in scene units is the unit's length, whatever rotation and
//! offset separate the frames.

use std::collections::HashMap;

/// The unit's length and how well the two camera layouts agree.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct UnitScale {
    /// Metres per scene unit: the median over camera pairs.
    pub metres_per_unit: f64,
    /// Camera pairs measured.
    pub pairs: usize,
    /// Median relative deviation of a pair's ratio from that median. A few per cent is the
    /// noise of a reconstruction; much more means the layouts are not one similarity apart
    /// (different cameras, or poses that did not register).
    pub spread: f64,
}

/// The layouts are taken as one similarity apart only within this spread.
pub const MAX_SPREAD: f64 = 0.02;
/// Fewer pairs cannot show a disagreement (two cameras make one pair, whose spread is 0).
pub const MIN_PAIRS: usize = 3;

impl UnitScale {
    pub fn consistent(&self) -> bool {
        self.pairs >= MIN_PAIRS && self.spread <= MAX_SPREAD
    }
}

/// Camera centres by photo name, in scene units and in metres; `None` where fewer than two
/// photos are in both or every shared pair is too close to measure.
pub fn unit_scale(
    scene: &HashMap<String, [f64; 3]>,
    truth: &HashMap<String, [f64; 3]>,
) -> Option<UnitScale> {
    let mut names: Vec<&String> = scene.keys().filter(|n| truth.contains_key(*n)).collect();
    names.sort();
    let mut pairs = Vec::new();
    for (i, a) in names.iter().enumerate() {
        for b in &names[i + 1..] {
            pairs.push((
                distance(scene[*a], scene[*b]),
                distance(truth[*a], truth[*b]),
            ));
        }
    }
    // Coincident centres (a rig, repeated frames) carry no length; "coincident" relative to
    // each layout's size, as units are arbitrary.
    let far = |f: fn(&(f64, f64)) -> f64| pairs.iter().map(f).fold(0.0, f64::max);
    let (units_far, metres_far) = (far(|p| p.0), far(|p| p.1));
    let mut ratios: Vec<f64> = pairs
        .iter()
        .filter(|(u, m)| *u > 1e-9 * units_far && *m > 1e-9 * metres_far)
        .map(|(u, m)| m / u)
        .collect();
    if ratios.is_empty() {
        return None;
    }
    let scale = median(&mut ratios);
    let mut deviations: Vec<f64> = ratios.iter().map(|r| (r / scale - 1.0).abs()).collect();
    Some(UnitScale {
        metres_per_unit: scale,
        pairs: ratios.len(),
        spread: median(&mut deviations),
    })
}

/// The camera centre of a `world_from_camera` matrix (its translation).
pub fn centre(world_from_camera: &[[f64; 4]; 4]) -> [f64; 3] {
    [
        world_from_camera[0][3],
        world_from_camera[1][3],
        world_from_camera[2][3],
    ]
}

fn distance(a: [f64; 3], b: [f64; 3]) -> f64 {
    a.iter()
        .zip(&b)
        .map(|(x, y)| (x - y) * (x - y))
        .sum::<f64>()
        .sqrt()
}

/// The middle value, or the mean of the two middle ones (`v` non-empty; sorted in place).
pub fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn layout() -> HashMap<String, [f64; 3]> {
        (0..6)
            .map(|i| {
                let a = f64::from(i) * 0.7;
                (
                    format!("{i:03}.png"),
                    [a.cos(), 0.3 * a.sin(), 0.1 * f64::from(i)],
                )
            })
            .collect()
    }

    /// Rotates about z by 0.4 rad, scales by `s` and moves by (5, −2, 1).
    fn similar(cams: &HashMap<String, [f64; 3]>, s: f64) -> HashMap<String, [f64; 3]> {
        let (sn, cs) = 0.4f64.sin_cos();
        cams.iter()
            .map(|(n, p)| {
                let q = [
                    s * (cs * p[0] - sn * p[1]) + 5.0,
                    s * (sn * p[0] + cs * p[1]) - 2.0,
                    s * p[2] + 1.0,
                ];
                (n.clone(), q)
            })
            .collect()
    }

    #[test]
    fn a_similarity_gives_its_scale_exactly() {
        let scene = layout();
        for s in [0.1, 1.0, 37.0] {
            let truth = similar(&scene, s);
            let u = unit_scale(&scene, &truth).expect("scale");
            assert!((u.metres_per_unit / s - 1.0).abs() < 1e-12, "{s}: {u:?}");
            assert_eq!(u.pairs, 15);
            assert!(u.spread < 1e-12 && u.consistent(), "{u:?}");
        }
        // Two cameras make one pair: agreement cannot be checked.
        let two: HashMap<_, _> = scene.iter().take(2).map(|(n, p)| (n.clone(), *p)).collect();
        let u = unit_scale(&two, &similar(&two, 3.0)).expect("one pair");
        assert_eq!(u.pairs, 1);
        assert!(!u.consistent());
    }

    #[test]
    fn photos_in_one_layout_only_are_left_out() {
        let scene = layout();
        let mut truth = similar(&scene, 2.0);
        truth.remove("000.png");
        truth.insert("999.png".into(), [100.0, 0.0, 0.0]);
        let u = unit_scale(&scene, &truth).expect("scale");
        assert_eq!(u.pairs, 10);
        assert!((u.metres_per_unit - 2.0).abs() < 1e-12);
    }

    #[test]
    fn unrelated_layouts_are_flagged() {
        let scene = layout();
        let mut truth = similar(&scene, 1.0);
        for (i, p) in truth.values_mut().enumerate() {
            p[0] += 0.8 * (i as f64).powi(2);
        }
        let u = unit_scale(&scene, &truth).expect("scale");
        assert!(!u.consistent(), "{u:?}");
    }

    #[test]
    fn no_shared_pair_gives_none() {
        let scene = layout();
        let one: HashMap<_, _> = [("000.png".to_owned(), [0.0; 3])].into();
        assert_eq!(unit_scale(&scene, &one), None);
        let coincident: HashMap<_, _> = scene.keys().map(|n| (n.clone(), [1.0; 3])).collect();
        assert_eq!(unit_scale(&scene, &coincident), None);
    }
}
