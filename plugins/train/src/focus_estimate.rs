//! Depth from defocus for the start of each photo's focus distance.
//!
//! The focus gradient of the CoC model is weak and unsigned (BENCHMARKS.md, dev-shelf): started
//! at the mean scene distance, the learned focus barely moves, and a wrong focus costs the
//! sharp base several dB. At the blur start there is better evidence: the warm-up 3DGS renders
//! each view with a per-pixel depth, and the photo is that scene blurred by the thin lens. So
//! for every candidate (focus, aperture) the render is blurred per pixel by a disc of radius
//! A·|1/d − 1/d_F| and compared with the photo; the best candidate gives the focus. Regions
//! the photo shows sharper than the render (its in-focus depth) are matched only by a focus
//! that leaves them unblurred, which is what makes the search informative even though the
//! warm-up render is itself soft.

/// One view's evidence, all at the same `width` × `height`.
pub struct FocusEvidence<'a> {
    pub photo: &'a [[f32; 3]],
    pub render: &'a [[f32; 3]],
    /// Distance from the camera centre per pixel; 0 where the render saw nothing.
    pub distance: &'a [f32],
    pub width: usize,
    pub height: usize,
}

/// The search runs near this width: larger images are box-reduced first, since defocus blur
/// spans many pixels and the grid's cost grows with pixels × disc area.
const ANALYSIS_WIDTH: usize = 100;
/// Disc radii of the blur layers, in analysis pixels.
const RADIUS_STEP: f64 = 0.25;
const MAX_RADIUS: f64 = 6.0;
/// Candidate focus positions across the view's inverse-distance range.
const FOCUS_STEPS: usize = 128;
/// Largest CoC radius over the scene's depth range, per aperture candidate (analysis pixels).
const SPANS: [f64; 9] = [0.5, 0.75, 1.0, 1.5, 2.0, 2.5, 3.0, 4.0, 6.0];

/// The focus distance (same units as `distance`) that best explains the photo as the render
/// seen through a thin lens; `None` when too little of the view has a depth.
pub fn estimate_focus(e: &FocusEvidence) -> Option<f64> {
    let view = reduce(e);
    let valid: Vec<usize> = (0..view.distance.len())
        .filter(|&i| view.distance[i] > 0.0)
        .collect();
    if valid.len() < 16 {
        return None;
    }
    let mut inv: Vec<f64> = valid.iter().map(|&i| 1.0 / view.distance[i]).collect();
    inv.sort_by(f64::total_cmp);
    // The bulk of what the view sees: a few far floaters must not stretch the search.
    let lo = inv[inv.len() / 20];
    let hi = inv[inv.len() - 1 - inv.len() / 20];
    let span = (hi - lo).max(1e-9);
    // Within the depths the view sees: past its farthest surface a focus only trades off
    // against the aperture (everything is in front of it), so the fit cannot place it there.
    let (from, to) = (lo, hi);

    let layers = disc_layers(&view.render, view.width, view.height);
    let mut best = (f64::INFINITY, 0.0);
    for step in 0..FOCUS_STEPS {
        let focus_inv = from + (to - from) * step as f64 / (FOCUS_STEPS - 1) as f64;
        for max_radius in SPANS {
            let a = max_radius / span;
            let mut err = 0.0;
            for &i in &valid {
                // Between two layers, linearly: the error then varies smoothly with the focus.
                let r = (a * (1.0 / view.distance[i] - focus_inv).abs()).min(MAX_RADIUS);
                let at = r / RADIUS_STEP;
                let k = (at.floor() as usize).min(layers.len() - 2);
                let t = at - k as f64;
                let (s0, s1, p) = (layers[k][i], layers[k + 1][i], view.photo[i]);
                err += (0..3)
                    .map(|c| (s0[c] + t * (s1[c] - s0[c]) - p[c]).abs())
                    .sum::<f64>();
            }
            if err < best.0 {
                best = (err, focus_inv);
            }
        }
    }
    Some(1.0 / best.1)
}

struct Reduced {
    photo: Vec<[f64; 3]>,
    render: Vec<[f64; 3]>,
    distance: Vec<f64>,
    width: usize,
    height: usize,
}

/// Box-reduces by the integer factor that brings the width near `ANALYSIS_WIDTH`; a cell's
/// distance is the mean of its seen pixels, or 0 when fewer than half were seen.
fn reduce(e: &FocusEvidence) -> Reduced {
    let k = (e.width / ANALYSIS_WIDTH).max(1);
    let (w, h) = (e.width / k, e.height / k);
    let mut out = Reduced {
        photo: vec![[0.0; 3]; w * h],
        render: vec![[0.0; 3]; w * h],
        distance: vec![0.0; w * h],
        width: w,
        height: h,
    };
    let area = (k * k) as f64;
    for y in 0..h {
        for x in 0..w {
            let (mut seen, mut dist) = (0usize, 0.0);
            let o = y * w + x;
            for dy in 0..k {
                for dx in 0..k {
                    let i = (y * k + dy) * e.width + x * k + dx;
                    for c in 0..3 {
                        out.photo[o][c] += f64::from(e.photo[i][c]) / area;
                        out.render[o][c] += f64::from(e.render[i][c]) / area;
                    }
                    if e.distance[i] > 0.0 && e.distance[i].is_finite() {
                        seen += 1;
                        dist += f64::from(e.distance[i]);
                    }
                }
            }
            if 2 * seen >= k * k && seen > 0 {
                out.distance[o] = dist / seen as f64;
            }
        }
    }
    out
}

/// The render blurred by a uniform disc of every radius on the grid (edges clamped).
fn disc_layers(image: &[[f64; 3]], w: usize, h: usize) -> Vec<Vec<[f64; 3]>> {
    let count = (MAX_RADIUS / RADIUS_STEP).round() as usize + 1;
    (0..count)
        .map(|k| {
            let r = k as f64 * RADIUS_STEP;
            let reach = r.floor() as isize;
            let taps: Vec<(isize, isize)> = (-reach..=reach)
                .flat_map(|dy| (-reach..=reach).map(move |dx| (dx, dy)))
                .filter(|&(dx, dy)| ((dx * dx + dy * dy) as f64) <= r * r + 0.5)
                .collect();
            let norm = 1.0 / taps.len() as f64;
            let mut out = vec![[0.0; 3]; w * h];
            for y in 0..h as isize {
                for x in 0..w as isize {
                    let mut sum = [0.0; 3];
                    for &(dx, dy) in &taps {
                        let sx = (x + dx).clamp(0, w as isize - 1) as usize;
                        let sy = (y + dy).clamp(0, h as isize - 1) as usize;
                        let p = image[sy * w + sx];
                        (0..3).for_each(|c| sum[c] += p[c]);
                    }
                    out[y as usize * w + x as usize] = sum.map(|s| s * norm);
                }
            }
            out
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A sharp, textured scene on a slanted plane from 0.5 to 2.5 (left to right).
    fn scene(w: usize, h: usize) -> (Vec<[f32; 3]>, Vec<f32>) {
        let mut state = 0x9E37_79B9_7F4A_7C15u64;
        let mut next = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 40) as f32 / (1u64 << 24) as f32
        };
        // Blocks of 2×2 pixels: texture at every scale the blur removes.
        let blocks: Vec<[f32; 3]> = (0..(w / 2 + 1) * (h / 2 + 1))
            .map(|_| [next(), next(), next()])
            .collect();
        let image = (0..w * h)
            .map(|i| blocks[(i / w / 2) * (w / 2 + 1) + (i % w) / 2])
            .collect();
        let distance = (0..w * h)
            .map(|i| 0.5 + 2.0 * (i % w) as f32 / (w - 1) as f32)
            .collect();
        (image, distance)
    }

    /// Thin-lens blur by direct per-pixel gather with the exact (unquantised) radius, in f64:
    /// independent of the estimator's layered discs.
    fn photograph(image: &[[f32; 3]], dist: &[f32], w: usize, focus: f64, a: f64) -> Vec<[f32; 3]> {
        let h = image.len() / w;
        (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as isize, (i / w) as isize);
                let r = a * (1.0 / f64::from(dist[i]) - 1.0 / focus).abs();
                let reach = r.ceil() as isize;
                let (mut sum, mut n) = ([0.0f64; 3], 0.0);
                for dy in -reach..=reach {
                    for dx in -reach..=reach {
                        if ((dx * dx + dy * dy) as f64) > r * r + 0.5 {
                            continue;
                        }
                        let sx = (x + dx).clamp(0, w as isize - 1) as usize;
                        let sy = (y + dy).clamp(0, h as isize - 1) as usize;
                        let p = image[sy * w + sx];
                        (0..3).for_each(|c| sum[c] += f64::from(p[c]));
                        n += 1.0;
                    }
                }
                sum.map(|s| (s / n) as f32)
            })
            .collect()
    }

    #[test]
    fn recovers_the_focus_of_a_thin_lens_photograph() {
        let (w, h) = (96, 48);
        let (sharp, distance) = scene(w, h);
        for focus in [0.8, 1.3, 2.1] {
            let photo = photograph(&sharp, &distance, w, focus, 2.5);
            let e = FocusEvidence {
                photo: &photo,
                render: &sharp,
                distance: &distance,
                width: w,
                height: h,
            };
            let found = estimate_focus(&e).unwrap();
            // What a focus error costs is a wrong CoC, A·|1/found − 1/focus| at every depth:
            // within a quarter pixel (far focus is loose in metres, tight in blur).
            let coc_error = 2.5 * (1.0 / found - 1.0 / focus).abs();
            assert!(coc_error <= 0.25, "focus {focus}: estimated {found}");
        }
    }

    #[test]
    fn a_soft_render_and_a_downscale_still_find_the_focus() {
        // Twice the analysis width: the estimator reduces first. The render is softened
        // everywhere (as a warm-up 3DGS fitted to blurred photos is) by a 1-pixel disc.
        let (w, h) = (200, 60);
        let (sharp, distance) = scene(w, h);
        let flat = vec![2.0f32; w * h];
        let soft = photograph(&sharp, &flat, w, 1.0, 2.0);
        let photo = photograph(&sharp, &distance, w, 1.1, 6.0);
        let e = FocusEvidence {
            photo: &photo,
            render: &soft,
            distance: &distance,
            width: w,
            height: h,
        };
        let found = estimate_focus(&e).unwrap();
        // 6 px per unit inverse distance at 200 wide is 3 px at the analysis width.
        let coc_error = 6.0 * (1.0 / found - 1.0 / 1.1).abs();
        assert!(coc_error <= 0.5, "estimated {found}");
    }

    #[test]
    fn a_view_without_depth_has_no_estimate() {
        let (w, h) = (40, 30);
        let (sharp, _) = scene(w, h);
        let nothing = vec![0.0f32; w * h];
        let e = FocusEvidence {
            photo: &sharp,
            render: &sharp,
            distance: &nothing,
            width: w,
            height: h,
        };
        assert_eq!(estimate_focus(&e), None);
    }
}
