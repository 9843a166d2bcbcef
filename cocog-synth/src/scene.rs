//! The procedural tabletop: a textured back wall and floor plus a few objects at different
//! depths, all made of flat, opaque Gaussians so surfaces are closed and occlude properly.
//!
//! World frame: x right, y away from the cameras, z up; one unit is about a metre. The cameras
//! sit near the origin at table height, so depth is roughly the world y coordinate.

use cocog_engine::reference::Gaussians64;
use glam::{DMat3, DQuat, DVec3};

use crate::rng::Rng;

/// SH band-0 constant: colour = 0.5 + C0 · f_dc.
const SH_C0: f64 = 0.282_094_791_773_878_14;

/// Gaussians under construction, with their colours kept for the COLMAP points.
#[derive(Clone, Debug, Default)]
pub struct SceneBuilder {
    g: Gaussians64,
    colors: Vec<[f64; 3]>,
}

/// A finished scene: degree-0 Gaussians, their display colours and the background colour.
#[derive(Clone, Debug)]
pub struct Scene {
    pub gaussians: Gaussians64,
    pub colors: Vec<[f64; 3]>,
    pub background: [f64; 3],
}

impl SceneBuilder {
    pub fn new() -> Self {
        Self::default()
    }

    pub fn len(&self) -> usize {
        self.colors.len()
    }

    pub fn is_empty(&self) -> bool {
        self.colors.is_empty()
    }

    /// A flat elliptical Gaussian centred at `centre` in the plane spanned by the unit vectors
    /// `u` and `n × u`, with standard deviations `sigma` along them; `rgb` in [0, 1].
    pub fn disc(
        &mut self,
        centre: DVec3,
        normal: DVec3,
        u: DVec3,
        sigma: [f64; 2],
        rgb: [f64; 3],
        opacity: f64,
    ) {
        let n = normal.normalize();
        let u = (u - n * u.dot(n)).normalize();
        let rot = DMat3::from_cols(u, n.cross(u), n);
        let q = DQuat::from_mat3(&rot).normalize();
        // Thin but not degenerate: a zero scale would make the 2D covariance singular edge-on.
        let thin = 0.02 * sigma[0].min(sigma[1]);
        let rgb = rgb.map(|c| c.clamp(0.0, 1.0));
        self.g.means.push(centre.to_array());
        self.g
            .log_scales
            .push([sigma[0].ln(), sigma[1].ln(), thin.ln()]);
        self.g.quats.push([q.w, q.x, q.y, q.z]);
        let o = opacity.clamp(1e-4, 1.0 - 1e-4);
        self.g.opacity_logits.push((o / (1.0 - o)).ln());
        self.g.sh.extend(rgb.map(|c| (c - 0.5) / SH_C0));
        self.colors.push(rgb);
    }

    pub fn finish(self, background: [f64; 3]) -> Scene {
        Scene {
            gaussians: Gaussians64 {
                sh_degree: 0,
                ..self.g
            },
            colors: self.colors,
            background,
        }
    }
}

/// Roughly the cameras' focal length in pixels at the default size: disc pitch is chosen
/// per depth so that discs are about `SCREEN_PITCH` pixels apart on screen.
const FOCAL_PX: f64 = 110.0;
const SCREEN_PITCH: f64 = 5.0;

/// Objects are small: finer discs there cost little and keep their checkers readable.
const OBJECT_DETAIL: f64 = 0.8;

/// World pitch that looks `SCREEN_PITCH` pixels wide at `depth`.
fn pitch_at(depth: f64) -> f64 {
    SCREEN_PITCH * depth / FOCAL_PX
}

/// How a surface is coloured, from its own 2D coordinates.
enum Texture {
    /// A checker of `square`-sized squares in two colours.
    Checker {
        a: [f64; 3],
        b: [f64; 3],
        square: f64,
    },
    /// Every disc a random pick from the colours: detail at the finest scale the discs allow.
    Mosaic(Vec<[f64; 3]>),
}

impl Texture {
    fn color(&self, uv: [f64; 2], rng: &mut Rng) -> [f64; 3] {
        let base = match self {
            Texture::Checker { a, b, square } => {
                let k = (uv[0] / square).floor() + (uv[1] / square).floor();
                if k.rem_euclid(2.0) < 1.0 { *a } else { *b }
            }
            Texture::Mosaic(colors) => colors[rng.below(colors.len())],
        };
        let shade = 1.0 + 0.06 * rng.normal();
        base.map(|c| c * shade)
    }
}

/// One planar patch: `origin + u·ea + v·eb` for v ∈ [0, lv] and |u| ≤ half_width(v), covered
/// by rows of discs whose pitch is `pitch(v)` (so it can grow with distance from the camera).
struct Patch<'a> {
    origin: DVec3,
    ea: DVec3,
    eb: DVec3,
    lv: f64,
    half_width: &'a dyn Fn(f64) -> f64,
    pitch: &'a dyn Fn(f64) -> f64,
    /// Pitch across rows relative to along them: > 1 for surfaces seen at a grazing angle,
    /// which keeps each disc's screen footprint (and its square tile bounding box) round.
    stretch: f64,
}

fn patch(sb: &mut SceneBuilder, rng: &mut Rng, p: &Patch, tex: &Texture) {
    let normal = p.ea.cross(p.eb);
    let mut v = 0.0;
    while v <= p.lv + 1e-9 {
        let h = (p.pitch)(v);
        let hw = (p.half_width)(v);
        let n = (2.0 * hw / h).round().max(1.0) as usize + 1;
        let hu = 2.0 * hw / (n - 1) as f64;
        for i in 0..n {
            let u = -hw + i as f64 * hu + 0.1 * hu * rng.normal();
            let vj = v + 0.1 * h * rng.normal();
            let rgb = tex.color([u, vj], rng);
            // 0.65 pitch: enough overlap that the background barely shows (alpha > 0.93)
            // without the cost of more (the rasterizer visits every disc over a tile).
            let sig = [0.65 * hu, 0.65 * h * p.stretch];
            sb.disc(
                p.origin + p.ea * u + p.eb * vj,
                normal,
                p.ea,
                sig,
                rgb,
                0.98,
            );
        }
        v += h * p.stretch;
    }
}

/// A sphere of discs on a Fibonacci lattice, checkered in latitude and longitude.
fn sphere(sb: &mut SceneBuilder, centre: DVec3, r: f64, depth: f64, a: [f64; 3], b: [f64; 3]) {
    let pitch = OBJECT_DETAIL * pitch_at(depth);
    let count = (4.0 * std::f64::consts::PI * r * r / (pitch * pitch)).ceil() as usize;
    for k in 0..count {
        let z = 1.0 - 2.0 * (k as f64 + 0.5) / count as f64;
        let th = k as f64 * 2.399_963_229_728_653;
        let rho = (1.0 - z * z).sqrt();
        let n = DVec3::new(rho * th.cos(), rho * th.sin(), z);
        let lon = (n.y.atan2(n.x) / std::f64::consts::TAU * 12.0).floor();
        let lat = ((z + 1.0) * 3.0).floor();
        let rgb = if (lon + lat).rem_euclid(2.0) < 1.0 {
            a
        } else {
            b
        };
        let tangent = if n.z.abs() < 0.9 { DVec3::Z } else { DVec3::X };
        sb.disc(centre + n * r, n, tangent, [0.75 * pitch; 2], rgb, 0.98);
    }
}

/// An axis-aligned box standing on the floor at `base`, about `depth` from the cameras.
fn cuboid(
    sb: &mut SceneBuilder,
    rng: &mut Rng,
    (base, size): (DVec3, DVec3),
    depth: f64,
    tex: &Texture,
) {
    let pitch = OBJECT_DETAIL * pitch_at(depth);
    let lo = base - DVec3::new(size.x / 2.0, size.y / 2.0, 0.0);
    let (x, y, z) = (DVec3::X, DVec3::Y, DVec3::Z);
    let mid = |a: f64| a / 2.0;
    // (origin at the middle of the face's first edge, across, along): each face wound so
    // that across × along points outwards; the back face is never seen.
    let faces = [
        (lo + x * mid(size.x), (-x, size.x), (z, size.z)), // front, −y
        (lo + y * mid(size.y), (y, size.y), (z, size.z)),  // left, −x
        (lo + x * size.x + y * mid(size.y), (-y, size.y), (z, size.z)), // right, +x
        (lo + x * mid(size.x) + z * size.z, (x, size.x), (y, size.y)), // top, +z
    ];
    for (origin, (ea, wa), (eb, lv)) in faces {
        let half = wa / 2.0;
        let p = Patch {
            origin,
            ea,
            eb,
            lv,
            half_width: &|_| half,
            pitch: &|_| pitch,
            stretch: 1.0,
        };
        patch(sb, rng, &p, tex);
    }
}

/// A colour of hue angle `h` (radians), saturation and value in [0, 1].
fn hue(h: f64, sat: f64, val: f64) -> [f64; 3] {
    std::array::from_fn(|k| {
        let base = 0.5 + 0.5 * (h + k as f64 * std::f64::consts::TAU / 3.0).cos();
        val * (1.0 - sat + sat * base)
    })
}

/// Two strongly contrasting colours (opposite hues, bright and dark): blur shows plainly.
fn contrasting(rng: &mut Rng) -> ([f64; 3], [f64; 3]) {
    let h = rng.unit() * std::f64::consts::TAU;
    (hue(h, 0.8, 0.95), hue(h + std::f64::consts::PI, 0.6, 0.3))
}

/// The default tabletop, deterministic in `seed`: about 1,900 Gaussians between roughly 0.55
/// and 3.4 units from the cameras, about `SCREEN_PITCH` pixels apart on screen everywhere.
pub fn tabletop(seed: u64) -> Scene {
    let mut rng = Rng::fork(seed, 1);
    let mut sb = SceneBuilder::new();
    let h0 = rng.unit() * std::f64::consts::TAU;
    let wall = Texture::Mosaic(vec![
        hue(h0, 0.7, 0.9),
        hue(h0 + 1.3, 0.6, 0.55),
        hue(h0 + 2.8, 0.5, 0.25),
        [0.93, 0.91, 0.86],
    ]);
    const WALL_Y: f64 = 3.2;
    let wall_patch = Patch {
        origin: DVec3::new(0.0, WALL_Y, 0.0),
        ea: DVec3::X,
        eb: DVec3::Z,
        lv: 1.4,
        half_width: &|_| 2.3,
        pitch: &|_| pitch_at(WALL_Y),
        stretch: 1.0,
    };
    patch(&mut sb, &mut rng, &wall_patch, &wall);

    // The floor runs from just below the lowest camera ray to the wall, and widens with the
    // view frustum; its pitch follows the distance so near tiles are as detailed as far ones.
    const FLOOR_Y0: f64 = 0.55;
    let floor_tex = Texture::Checker {
        a: [0.58, 0.4, 0.24],
        b: [0.9, 0.86, 0.76],
        square: 0.2,
    };
    let floor_patch = Patch {
        origin: DVec3::new(0.0, FLOOR_Y0, 0.0),
        ea: DVec3::X,
        eb: DVec3::Y,
        lv: WALL_Y - FLOOR_Y0,
        half_width: &|v| 0.65 * (FLOOR_Y0 + v) + 0.35,
        pitch: &|v| pitch_at(FLOOR_Y0 + v),
        stretch: 2.0,
    };
    patch(&mut sb, &mut rng, &floor_patch, &floor_tex);

    let jitter = |rng: &mut Rng, v: DVec3| {
        v + DVec3::new(rng.range(-0.05, 0.05), rng.range(-0.05, 0.05), 0.0)
    };
    let near = jitter(&mut rng, DVec3::new(-0.2, 0.62, 0.1));
    let (a, b) = contrasting(&mut rng);
    sphere(&mut sb, near, 0.1, 0.6, a, b);
    let mid = jitter(&mut rng, DVec3::new(0.28, 1.3, 0.0));
    let (a, b) = contrasting(&mut rng);
    let tex = Texture::Checker { a, b, square: 0.08 };
    cuboid(
        &mut sb,
        &mut rng,
        (mid, DVec3::new(0.24, 0.2, 0.26)),
        1.3,
        &tex,
    );
    let far = jitter(&mut rng, DVec3::new(-0.55, 2.0, 0.25));
    let (a, b) = contrasting(&mut rng);
    sphere(&mut sb, far, 0.25, 2.0, a, b);
    let back_box = jitter(&mut rng, DVec3::new(0.75, 2.6, 0.0));
    let (a, b) = contrasting(&mut rng);
    let tex = Texture::Checker { a, b, square: 0.14 };
    cuboid(
        &mut sb,
        &mut rng,
        (back_box, DVec3::new(0.3, 0.25, 0.55)),
        2.6,
        &tex,
    );
    sb.finish([0.5, 0.5, 0.5])
}
