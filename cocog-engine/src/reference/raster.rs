//! f64 reference of tile binning, front-to-back compositing and its back-to-front backward.

use super::project::{Projected, ProjectedGrad, project, project_backward};
use super::{Gaussians64, Grads64};
use crate::types::{ALPHA_MAX, ALPHA_MIN, Camera, T_MIN, TILE_SIZE};

/// One rendered image, row-major pixels.
#[derive(Clone, Debug, PartialEq)]
pub struct Image64 {
    pub width: u32,
    pub height: u32,
    pub color: Vec<[f64; 3]>,
    /// 1 − final transmittance.
    pub alpha: Vec<f64>,
    /// Σ wᵢ·zᵢ (camera z), not normalised by alpha.
    pub depth: Vec<f64>,
}

/// A Gaussian's contribution to one pixel, as the forward composited it.
struct Hit {
    index: usize,
    alpha: f64,
    /// Whether `alpha` hit the `ALPHA_MAX` ceiling (then it has no gradient).
    saturated: bool,
    gauss: f64,
    t_before: f64,
    delta: [f64; 2],
}

fn tile_lists(proj: &[Option<Projected>], cam: &Camera) -> Vec<Vec<usize>> {
    let (tx, ty) = cam.tiles();
    let mut lists = vec![Vec::new(); (tx * ty) as usize];
    for (i, p) in proj.iter().enumerate() {
        let Some(p) = p else { continue };
        for y in p.tile_min[1]..p.tile_max[1] {
            for x in p.tile_min[0]..p.tile_max[0] {
                lists[(y * tx + x) as usize].push(i);
            }
        }
    }
    // The GPU sorts by (tile, depth) stably from Gaussian order, so ties keep index order.
    for l in &mut lists {
        l.sort_by(|&a, &b| {
            let (da, db) = (
                proj[a].map_or(0.0, |p| p.depth),
                proj[b].map_or(0.0, |p| p.depth),
            );
            da.total_cmp(&db).then(a.cmp(&b))
        });
    }
    lists
}

fn composite(px: u32, py: u32, list: &[usize], proj: &[Option<Projected>]) -> (Vec<Hit>, f64) {
    let centre = [f64::from(px) + 0.5, f64::from(py) + 0.5];
    let mut hits = Vec::new();
    let mut t = 1.0;
    for &i in list {
        let Some(p) = proj[i] else { continue };
        let d = [p.mean2d[0] - centre[0], p.mean2d[1] - centre[1]];
        let power =
            -0.5 * (p.conic[0] * d[0] * d[0] + p.conic[2] * d[1] * d[1]) - p.conic[1] * d[0] * d[1];
        if power > 0.0 {
            continue;
        }
        let gauss = power.exp();
        let raw = p.opacity * gauss;
        let alpha = raw.min(ALPHA_MAX);
        if alpha < ALPHA_MIN {
            continue;
        }
        let next_t = t * (1.0 - alpha);
        if next_t < T_MIN {
            break;
        }
        hits.push(Hit {
            index: i,
            alpha,
            saturated: raw > ALPHA_MAX,
            gauss,
            t_before: t,
            delta: d,
        });
        t = next_t;
    }
    (hits, t)
}

/// Renders one image of `g` seen by `cam` over `background`.
pub fn render(g: &Gaussians64, cam: &Camera, background: [f64; 3]) -> Image64 {
    let proj: Vec<_> = (0..g.len()).map(|i| project(g, i, cam)).collect();
    let lists = tile_lists(&proj, cam);
    let (tx, _) = cam.tiles();
    let npix = (cam.width * cam.height) as usize;
    let mut img = Image64 {
        width: cam.width,
        height: cam.height,
        color: vec![[0.0; 3]; npix],
        alpha: vec![0.0; npix],
        depth: vec![0.0; npix],
    };
    for py in 0..cam.height {
        for px in 0..cam.width {
            let list = &lists[((py / TILE_SIZE) * tx + px / TILE_SIZE) as usize];
            let (hits, t) = composite(px, py, list, &proj);
            let pix = (py * cam.width + px) as usize;
            let mut c = background.map(|b| b * t);
            let mut depth = 0.0;
            for h in &hits {
                let p = proj[h.index].unwrap_or_else(|| unreachable!("hits are projected"));
                let w = h.alpha * h.t_before;
                for k in 0..3 {
                    c[k] += p.color[k] * w;
                }
                depth += p.depth * w;
            }
            img.color[pix] = c;
            img.alpha[pix] = 1.0 - t;
            img.depth[pix] = depth;
        }
    }
    img
}

/// Gradients of a loss whose derivatives with respect to the outputs of `render` are
/// `v_color`, `v_alpha` and `v_depth`.
pub fn render_backward(
    g: &Gaussians64,
    cam: &Camera,
    background: [f64; 3],
    v_color: &[[f64; 3]],
    v_alpha: &[f64],
    v_depth: &[f64],
) -> Grads64 {
    let v_proj = raster_backward(g, cam, background, v_color, v_alpha, v_depth);
    let mut grads = Grads64::zeros_like(g);
    for (i, vp) in v_proj.iter().enumerate() {
        project_backward(g, i, cam, vp, &mut grads);
    }
    grads
}

/// The compositing half of `render_backward`: gradients with respect to each Gaussian's
/// screen-space footprint.
pub fn raster_backward(
    g: &Gaussians64,
    cam: &Camera,
    background: [f64; 3],
    v_color: &[[f64; 3]],
    v_alpha: &[f64],
    v_depth: &[f64],
) -> Vec<ProjectedGrad> {
    let proj: Vec<_> = (0..g.len()).map(|i| project(g, i, cam)).collect();
    let lists = tile_lists(&proj, cam);
    let (tx, _) = cam.tiles();
    let mut v_proj = vec![ProjectedGrad::default(); g.len()];
    for py in 0..cam.height {
        for px in 0..cam.width {
            let list = &lists[((py / TILE_SIZE) * tx + px / TILE_SIZE) as usize];
            let (hits, t_final) = composite(px, py, list, &proj);
            let pix = (py * cam.width + px) as usize;
            let (vc, va, vd) = (v_color[pix], v_alpha[pix], v_depth[pix]);
            // Colour and depth of everything behind the current Gaussian, background included.
            let mut behind = background.map(|b| b * t_final);
            let mut behind_depth = 0.0;
            for h in hits.iter().rev() {
                let p = proj[h.index].unwrap_or_else(|| unreachable!("hits are projected"));
                let vp = &mut v_proj[h.index];
                let w = h.alpha * h.t_before;
                let one_minus = 1.0 - h.alpha;
                let mut v_a = va * t_final / one_minus;
                for k in 0..3 {
                    vp.v_color[k] += w * vc[k];
                    v_a += vc[k] * (h.t_before * p.color[k] - behind[k] / one_minus);
                    behind[k] += p.color[k] * w;
                }
                vp.v_depth += w * vd;
                v_a += vd * (h.t_before * p.depth - behind_depth / one_minus);
                behind_depth += p.depth * w;
                if h.saturated {
                    continue;
                }
                vp.v_opacity += v_a * h.gauss;
                let v_power = v_a * h.alpha;
                let [dx, dy] = h.delta;
                let [ca, cb, cc] = p.conic;
                vp.v_mean2d[0] -= v_power * (ca * dx + cb * dy);
                vp.v_mean2d[1] -= v_power * (cc * dy + cb * dx);
                vp.v_conic[0] -= v_power * 0.5 * dx * dx;
                vp.v_conic[1] -= v_power * dx * dy;
                vp.v_conic[2] -= v_power * 0.5 * dy * dy;
            }
        }
    }
    v_proj
}
