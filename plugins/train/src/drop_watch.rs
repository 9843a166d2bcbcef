//! Spots a training collapse in the logged PSNR readings, so a user sees it in the log and
//! at the end of the run rather than only in the test scores.
//!
//! Each reading is the PSNR of one (different) training view, so single readings differ by
//! the views' difficulty (by 5 dB between blurred views of one scene, measured). The watch
//! compares the mean of the last `window` readings — about one pass over the views — with the
//! best such mean so far; a drop starts when it falls more than `DROP_DB` below that best.

use std::collections::VecDeque;

/// A fall of this much is far beyond view-to-view differences once averaged over a window
/// (a collapse such as INRIA's world-space prune on forward-facing captures falls 20+ dB).
pub const DROP_DB: f64 = 3.0;

/// The start of a fall of more than `DROP_DB` below the best smoothed PSNR.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PsnrDrop {
    /// The reading at which the smoothed PSNR was first more than `DROP_DB` below its best.
    pub iteration: u32,
    pub best: f64,
    pub best_iteration: u32,
    pub smoothed: f64,
}

#[derive(Clone, Debug)]
pub struct DropWatch {
    size: usize,
    window: VecDeque<f64>,
    best: Option<(f64, u32)>,
    /// Inside a drop: no new one is reported until the PSNR is back within `DROP_DB`.
    falling: bool,
    last: Option<PsnrDrop>,
}

impl DropWatch {
    /// Smooths over `views` readings (one per training view, if each is read once), at
    /// least 3 and at most 30.
    pub fn new(views: usize) -> Self {
        Self {
            size: views.clamp(3, 30),
            window: VecDeque::new(),
            best: None,
            falling: false,
            last: None,
        }
    }

    /// Takes the reading at `iteration`; returns the drop it starts, if it starts one.
    pub fn observe(&mut self, iteration: u32, psnr: f64) -> Option<PsnrDrop> {
        if !psnr.is_finite() {
            return None;
        }
        if self.window.len() == self.size {
            self.window.pop_front();
        }
        self.window.push_back(psnr);
        if self.window.len() < self.size {
            return None;
        }
        let smoothed = self.window.iter().sum::<f64>() / self.size as f64;
        let (best, best_iteration) = match self.best {
            Some((b, _)) if b >= smoothed => self.best.expect("matched Some"),
            _ => {
                self.best = Some((smoothed, iteration));
                (smoothed, iteration)
            }
        };
        if smoothed < best - DROP_DB {
            if !self.falling {
                self.falling = true;
                let drop = PsnrDrop {
                    iteration,
                    best,
                    best_iteration,
                    smoothed,
                };
                self.last = Some(drop);
                return Some(drop);
            }
        } else {
            self.falling = false;
        }
        None
    }

    /// The most recent drop, if any happened.
    pub fn last(&self) -> Option<PsnrDrop> {
        self.last
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(readings: &[f64]) -> (Vec<u32>, Option<PsnrDrop>) {
        let mut w = DropWatch::new(3);
        let starts = readings
            .iter()
            .enumerate()
            .filter_map(|(i, &p)| w.observe(100 * (i as u32 + 1), p))
            .map(|d| d.iteration)
            .collect();
        (starts, w.last())
    }

    #[test]
    fn view_to_view_scatter_is_averaged_over_a_pass() {
        // Readings that cycle through 21 views whose PSNRs differ by 5 dB (blurred views):
        // a 3-reading window would see 3 dB "drops"; a pass-long one sees a flat curve.
        let views: Vec<f64> = (0..21)
            .map(|v| 32.0 + 5.0 * f64::from(v % 4) / 3.0)
            .collect();
        let mut w = DropWatch::new(21);
        for i in 0..200u32 {
            assert_eq!(
                w.observe(i, views[(i as usize * 8) % 21]),
                None,
                "reading {i}"
            );
        }
    }

    #[test]
    fn rising_and_noisy_curves_raise_nothing() {
        // ±2 dB view-to-view scatter around a rising trend.
        let noisy: Vec<f64> = (0..60)
            .map(|i| 20.0 + 0.2 * f64::from(i) + if i % 2 == 0 { 2.0 } else { -2.0 })
            .collect();
        assert_eq!(run(&noisy), (vec![], None));
    }

    #[test]
    fn a_collapse_is_reported_where_it_starts_and_only_once() {
        let mut p = vec![30.0, 35.0, 38.0, 40.0, 40.0, 40.0];
        p.extend([15.0, 15.0, 16.0, 17.0]);
        let (starts, last) = run(&p);
        // Smoothed: … 40, then (40+40+15)/3 = 31.7 < 37 at reading 7 (iteration 700).
        assert_eq!(starts, vec![700]);
        let last = last.unwrap();
        assert_eq!((last.best, last.best_iteration), (40.0, 600));
        assert!((last.smoothed - 95.0 / 3.0).abs() < 1e-12);
    }

    #[test]
    fn a_recovery_then_a_second_fall_moves_the_last_drop() {
        let p = [
            30.0, 30.0, 30.0, 20.0, 20.0, 20.0, 30.0, 30.0, 30.0, 20.0, 20.0, 20.0,
        ];
        let (starts, last) = run(&p);
        assert_eq!(starts, vec![400, 1000]);
        assert_eq!(last.unwrap().iteration, 1000);
        assert_eq!(run(&[f64::NAN, 1.0]).0, Vec::<u32>::new());
    }
}
