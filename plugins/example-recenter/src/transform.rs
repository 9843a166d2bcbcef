//! The similarity transform x' = s·x + t and how each scene quantity follows it.

use std::path::Path;

use cocog_formats::ply::{read_points, read_splats, write_points, write_splats};
use cocog_pipeline::{Context, Scene, StageError};

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Similarity {
    pub scale: f64,
    pub translation: [f64; 3],
}

fn centre(m: &[[f64; 4]; 4]) -> [f64; 3] {
    [m[0][3], m[1][3], m[2][3]]
}

impl Similarity {
    /// Mean camera centre to the origin, farthest camera at `radius`. `None` when all
    /// cameras coincide, since no scale can be chosen then.
    pub fn normalising(scene: &Scene, radius: f64) -> Option<Self> {
        let centres: Vec<[f64; 3]> = scene
            .views
            .iter()
            .map(|v| centre(&v.world_from_camera))
            .collect();
        if centres.is_empty() {
            return None;
        }
        let n = centres.len() as f64;
        let mean = [0, 1, 2].map(|k| centres.iter().map(|c| c[k]).sum::<f64>() / n);
        let far = centres
            .iter()
            .map(|c| (0..3).map(|k| (c[k] - mean[k]).powi(2)).sum::<f64>().sqrt())
            .fold(0.0, f64::max);
        if !(far > 1e-12 && far.is_finite()) {
            return None;
        }
        let scale = radius / far;
        Some(Self {
            scale,
            translation: mean.map(|m| -scale * m),
        })
    }

    pub fn point(&self, p: [f64; 3]) -> [f64; 3] {
        [0, 1, 2].map(|k| self.scale * p[k] + self.translation[k])
    }

    /// Poses keep their rotation; lengths scale. The CoC diameter K·|1/d − 1/d_F| stays
    /// the same in pixels when d and d_F scale by s only if K scales by s too.
    pub fn apply_to_scene(&self, scene: &mut Scene) {
        for v in &mut scene.views {
            let c = self.point(centre(&v.world_from_camera));
            for (row, value) in v.world_from_camera.iter_mut().zip(c) {
                row[3] = value;
            }
            if let Some(lens) = &mut v.lens {
                lens.focus_distance *= self.scale;
                lens.aperture = lens.aperture.map(|k| k * self.scale);
            }
        }
        if let Some(b) = &mut scene.bounds {
            b.near *= self.scale;
            b.far *= self.scale;
        }
    }
}

/// Makes the scene's paths absolute (so the new scene still finds its images) and writes
/// transformed copies of its point cloud and Gaussians into `out`.
pub fn carry_files(
    scene: &mut Scene,
    input: &Path,
    out: &Path,
    sim: &Similarity,
    ctx: &dyn Context,
) -> Result<(), StageError> {
    let input = input.canonicalize().map_err(|e| StageError::io(input, e))?;
    if let Some(stored) = scene.points.clone() {
        let mut cloud = read_points(&Scene::resolve(&input, &stored)).map_err(StageError::other)?;
        for p in cloud.positions.chunks_exact_mut(3) {
            let q = sim.point([p[0], p[1], p[2]].map(f64::from));
            p.copy_from_slice(&q.map(|v| v as f32));
        }
        write_points(&out.join("points.ply"), &cloud).map_err(StageError::other)?;
        scene.points = Some("points.ply".to_owned());
        ctx.info(&format!("recenter: moved {} points", cloud.len()));
    }
    if let Some(stored) = scene.gaussians.clone() {
        let mut g = read_splats(Path::new(&stored)).map_err(StageError::other)?;
        for p in g.means.chunks_exact_mut(3) {
            let q = sim.point([p[0], p[1], p[2]].map(f64::from));
            p.copy_from_slice(&q.map(|v| v as f32));
        }
        let ln_s = sim.scale.ln() as f32;
        for s in &mut g.log_scales {
            *s += ln_s;
        }
        write_splats(&out.join("gaussians.ply"), &g, None).map_err(StageError::other)?;
        scene.gaussians = Some("gaussians.ply".to_owned());
        ctx.info(&format!("recenter: moved {} Gaussians", g.len()));
    }
    for v in &mut scene.views {
        if v.depth.take().is_some() {
            // Depth maps hold distances in the old units; rather than point at maps
            // that are now wrong by a factor, drop them (render can regenerate depth).
            ctx.warn(&format!(
                "recenter: view {}: dropped its depth map (stored in the old scene units)",
                v.name
            ));
        }
    }
    Ok(())
}
