//! The trained Gaussians checked before they are written.

use cocog_formats::Splats;
use cocog_pipeline::{Context, StageError};

/// Drops the Gaussians holding a NaN or infinite value or an all-zero rotation, which no
/// reader accepts, with a warning; more than 1 % of them means the run diverged, and
/// `diverged` makes that error from what went wrong (see `Session::diverged_error`).
/// Gaussians pushed past f32's range vanish from every render, so the loss can stay a number
/// while they become infinite.
pub(super) fn keep_writable(
    splats: &mut Splats,
    iterations: u32,
    ctx: &dyn Context,
    diverged: impl FnOnce(String) -> StageError,
) -> Result<(), StageError> {
    let keep = splats.writable_mask();
    let bad = keep.iter().filter(|k| !**k).count();
    if bad == 0 {
        return Ok(());
    }
    let total = splats.len();
    if bad * 100 > total {
        let first = keep.iter().position(|k| !k).unwrap_or(0);
        return Err(diverged(format!(
            "after iteration {iterations}, {bad} of {total} Gaussians hold NaN or infinite \
             values or an all-zero rotation (the first: Gaussian {first})"
        )));
    }
    splats.retain(&keep);
    ctx.warn(&format!(
        "dropped {bad} of {total} Gaussians whose parameters were NaN or infinite (or whose \
         rotation was all zero) after iteration {iterations}"
    ));
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use cocog_pipeline::NullContext;

    fn splats(n: usize) -> Splats {
        let mut s = Splats::with_capacity(n, 1);
        for i in 0..n {
            s.means.extend([i as f32, 0.0, 1.0]);
            s.log_scales.extend([-2.0; 3]);
            s.rotations.extend([1.0, 0.0, 0.0, 0.0]);
            s.opacities.push(0.5);
            s.sh_dc.extend([0.1; 3]);
            s.sh_rest.extend([0.0; 9]);
        }
        s
    }

    #[test]
    fn a_few_broken_gaussians_are_dropped_and_many_stop_the_run() {
        let mut s = splats(300);
        s.sh_rest[9 * 7 + 4] = f32::NAN;
        s.log_scales[3 * 150 + 2] = f32::INFINITY;
        s.rotations[4 * 160..4 * 161].fill(0.0);
        keep_writable(&mut s, 30, &NullContext, StageError::Options).unwrap();
        assert_eq!(s.len(), 297);
        assert_eq!(s.sh_rest.len(), 297 * 9);
        // The survivors keep their order: Gaussian 7 is gone, 8 moved up.
        assert_eq!(
            (s.means[3 * 6], s.means[3 * 7], s.means[3 * 148]),
            (6.0, 8.0, 149.0)
        );
        assert_eq!((s.means[3 * 149], s.means[3 * 158]), (151.0, 161.0));

        let mut s = splats(200);
        for i in [3, 90, 199] {
            s.rotations[4 * i + 1] = f32::NEG_INFINITY;
        }
        let e = keep_writable(&mut s, 30, &NullContext, StageError::Options)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains(
                "after iteration 30, 3 of 200 Gaussians hold NaN or infinite values or an \
                 all-zero rotation (the first: Gaussian 3)"
            ),
            "{e}"
        );
        assert_eq!(s.len(), 200);
    }
}
