//! Room for the renderer's (tile, Gaussian) intersections. A step never waits to learn how
//! many it needs: the count comes back a few steps late, room grows ahead of it, and a step
//! that still overflowed was skipped on the GPU and its view is trained again.

use cocog_engine::{Batch, ImageSpec};

use super::{Trainer, bands};
use crate::TrainError;

/// Room kept above the largest count seen.
const HEADROOM: f64 = 1.5;
/// Grow once a count comes this close to the room.
const GROW_AT: f64 = 0.8;

impl Trainer<'_> {
    /// Room for the most intersections any training view (or band of one, `bands.rs`)
    /// needs now, with headroom: one blocking count per view and band, at start-up only.
    pub(super) fn measure_capacity(&mut self) -> Result<u32, TrainError> {
        let mut batch = self.batch.take().ok_or(TrainError::Poisoned)?;
        let result = self.most_needed(&mut batch);
        self.batch = Some(batch);
        Ok(with_headroom(result?))
    }

    fn most_needed(&mut self, batch: &mut Batch) -> Result<u32, TrainError> {
        let ctx = self.ctx;
        let limit = self.frame_binding_limit();
        let mut most = 0u32;
        for camera in self.cameras.clone() {
            self.aim(batch, camera, self.config.background)?;
            let frame = batch.images[0];
            let bands = bands::plan(camera.width, camera.height, limit)
                .map_err(TrainError::Invalid)?
                .unwrap_or_default();
            let mut specs: Vec<ImageSpec> = bands
                .iter()
                .map(|b| frame.rows(b.rendered.0, b.rendered.1 - b.rendered.0))
                .collect();
            if specs.is_empty() {
                specs.push(frame);
            }
            for spec in specs {
                batch.set_images(ctx, vec![spec])?;
                let mut rec = ctx.recorder();
                // Room for none: only the count in `status` is wanted.
                let state = self
                    .renderer
                    .encode_forward(&mut rec, &mut self.ws, batch, 0);
                rec.submit();
                most = most.max(ctx.read::<u32>(&state.status, 2)?[1]);
            }
        }
        Ok(most)
    }

    /// The most room a binding holds: a step that needs more cannot run on this adapter.
    pub(super) fn most_intersections(&self) -> u32 {
        self.renderer.max_intersections(self.ctx)
    }

    /// Room set to `capacity`, held within a binding.
    pub(super) fn set_room(&mut self, capacity: u32) {
        self.capacity = capacity.min(self.most_intersections());
    }

    /// A step needed `needed` intersections: grow the room before later steps run out.
    pub(super) fn note_intersections(&mut self, needed: u32) {
        if f64::from(needed) > GROW_AT * f64::from(self.capacity) {
            self.set_room(self.capacity.max(with_headroom(needed)));
        }
    }

    /// Densification changed the Gaussian count from `before`: scale the room with it, since
    /// the counts of the next few steps arrive too late to prevent an overflow.
    pub(super) fn grow_capacity_with(&mut self, before: u32) {
        let ratio = f64::from(self.num_gaussians()) / f64::from(before.max(1));
        if ratio > 1.0 {
            let grown = (f64::from(self.capacity) * ratio).ceil();
            self.set_room(grown.min(f64::from(u32::MAX)) as u32);
        }
    }
}

fn with_headroom(count: u32) -> u32 {
    ((f64::from(count) * HEADROOM)
        .ceil()
        .min(f64::from(u32::MAX)) as u32)
        .max(1024)
}
