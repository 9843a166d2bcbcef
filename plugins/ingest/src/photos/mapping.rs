//! Incremental mapping with the focal length held at its prior (EXIF, else COLMAP's 1.2 × the
//! longer side) and the distortion refined, then one global bundle adjustment that refines both.
//!
//! Why: COLMAP refines the focal length from the first image pair on. On a narrow,
//! forward-facing rig of defocused photos that early estimate has almost nothing to go on, and
//! the mapper wanders off and never comes back: on dev-shelf, 5 of 5 feature databases gave a
//! focal length of 2, 6, 287, 299 or 1181 px against 389, with 10, 11, 24, 24 or 16 of 24
//! photos registered and rotations off by 1.4–5.7°. With the focal length held until every
//! photo is in, then refined over all of them, the same databases gave 24 of 24, focal
//! 379–404 px and rotations within 0.26–0.47° (BENCHMARKS.md, "ingest photos").
//!
//! The distortion is not held: a real lens's distortion cannot be absorbed by poses, and with it
//! held at 0 the final adjustment on sharp-dev warped through k = −0.08 ended in a wrong
//! minimum in 4 of 7 runs (focal 706 px, rotations off by 1.8–3.3°). Refined while mapping, it
//! takes up what the held focal length leaves, and the final adjustment starts near the truth.

use std::path::Path;

use cocog_pipeline::{Context, StageError};

use super::colmap::{Args, Colmap};
use super::model::{Mapped, read_models};
use super::settings::PhotoSettings;

/// How the intrinsics of the kept model were found, for the summary.
#[derive(Clone, Copy, PartialEq, Debug)]
pub(crate) enum Intrinsics {
    /// Focal length held at the prior while mapping, then refined by a final bundle adjustment.
    HeldThenRefined,
    /// Refined all along by COLMAP's mapper (`--free-intrinsics`, or the fallback).
    Free,
}

impl Intrinsics {
    pub fn describe(self) -> &'static str {
        match self {
            Self::HeldThenRefined => {
                "focal length held at the prior while mapping, then bundle-adjusted"
            }
            Self::Free => "refined while mapping (COLMAP's mapper)",
        }
    }
}

/// One photo set's mapping: COLMAP, the options, the feature database.
pub(crate) struct Mapper<'a> {
    pub cm: &'a Colmap,
    pub settings: &'a PhotoSettings,
    pub db: &'a Path,
    pub photos: &'a Path,
    pub photos_n: usize,
    pub ctx: &'a dyn Context,
}

impl Mapper<'_> {
    /// Runs the mapper into `out` and returns its models, largest first.
    fn run(&self, out: &Path, hold: bool) -> Result<Vec<Mapped>, StageError> {
        std::fs::create_dir_all(out).map_err(|e| StageError::io(out, e))?;
        let mut mapper = Args::new("mapper")
            .arg("database_path", self.db.display())
            .arg("image_path", self.photos.display())
            .arg("output_path", out.display())
            .total(self.photos_n);
        if self.settings.narrow_baseline {
            // COLMAP's 16° initial pair and 1.5° point angles assume orbits; forward-facing
            // rigs see a few degrees at most, and then the mapper starts from a poor pair or
            // stalls.
            mapper = mapper
                .tune("Mapper.init_min_tri_angle", 2)
                .tune("Mapper.tri_min_angle", 0.5)
                .tune("Mapper.filter_min_tri_angle", 0.5);
        }
        if hold {
            mapper = mapper.arg("Mapper.ba_refine_focal_length", 0);
        }
        let task = if hold { "map" } else { "map (free intrinsics)" };
        self.cm.run(mapper, task, self.ctx)?;
        read_models(out)
    }

    /// Maps the photos; returns COLMAP's models (largest first) and how their intrinsics were
    /// found. With the focal length held, a largest model of fewer than `need` photos (a prior far
    /// from the truth can do that) is retried with COLMAP's free intrinsics, and the run that
    /// registered more photos is kept.
    pub fn map(&self, work: &Path, need: usize) -> Result<(Vec<Mapped>, Intrinsics), StageError> {
        let sparse = work.join("sparse");
        if self.settings.free_intrinsics {
            return Ok((self.run(&sparse, false)?, Intrinsics::Free));
        }
        let held = self.run(&sparse, true)?;
        let size = |m: &[Mapped]| m.first().map_or(0, |m| m.model.images.len());
        if size(&held) >= need {
            return Ok((held, Intrinsics::HeldThenRefined));
        }
        let free = self.run(&work.join("sparse-free-intrinsics"), false)?;
        let (h, f) = (size(&held), size(&free));
        self.ctx.warn(&format!(
            "with the focal length held at its prior COLMAP registered {h} of {} photos; \
             refining it while mapping registered {f}; keeping the {}",
            self.photos_n,
            if f > h { "latter" } else { "former" }
        ));
        Ok(if f > h {
            (free, Intrinsics::Free)
        } else {
            (held, Intrinsics::HeldThenRefined)
        })
    }
}

/// The final bundle adjustment over every registered photo, refining focal length and
/// distortion (the principal point stays at the centre, as COLMAP leaves it); replaces `kept`.
pub(crate) fn refine(
    cm: &Colmap,
    kept: &mut Mapped,
    work: &Path,
    ctx: &dyn Context,
) -> Result<(), StageError> {
    let out = work.join("refined");
    std::fs::create_dir_all(&out).map_err(|e| StageError::io(&out, e))?;
    cm.run(
        Args::new("bundle_adjuster")
            .arg("input_path", kept.dir.display())
            .arg("output_path", out.display())
            .arg("BundleAdjustment.refine_focal_length", 1)
            .arg("BundleAdjustment.refine_extra_params", 1)
            .arg("BundleAdjustment.refine_principal_point", 0),
        "refine intrinsics",
        ctx,
    )?;
    let model = cocog_formats::colmap::read_model(&out).map_err(crate::input_error)?;
    *kept = Mapped { dir: out, model };
    Ok(())
}
