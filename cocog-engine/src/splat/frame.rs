//! One image of any size. A frame whose colour buffer, or whose list of tile intersections,
//! would outgrow one buffer binding (lavapipe binds 128 MiB: 8.4 Mpixel of rgba) is rendered
//! in bands of rows, each band an image of its own (`ImageSpec::rows`).

use super::batch::{Batch, ImageSpec};
use super::renderer::Renderer;
use super::state::RenderedImage;
use crate::EngineError;
use crate::core::GpuContext;
use crate::types::TILE_SIZE;

/// A rendered frame and how many bands it took.
#[derive(Clone, Debug)]
pub struct Frame {
    pub image: RenderedImage,
    pub bands: u32,
}

/// Bytes of one rgba f32 pixel, the widest per-pixel buffer of a forward pass.
const RGBA_BYTES: u64 = 16;

impl Renderer {
    /// Renders `spec`, a whole frame of the Gaussians in `batch`, re-aiming the batch
    /// (`Batch::set_images`) at each band. Bands are whole tile rows, as tall as the colour
    /// buffer's binding allows, and halved while their intersections do not fit one; a frame
    /// that fits renders in one piece, exactly as `forward` renders it. Blocks until done.
    pub fn render_frame(
        &self,
        ctx: &GpuContext,
        batch: &mut Batch,
        spec: ImageSpec,
    ) -> Result<Frame, EngineError> {
        let (w, h) = (spec.camera.width, spec.camera.height);
        let limit = self.binding_limit(ctx);
        let tile_rows = limit / (RGBA_BYTES * u64::from(w) * u64::from(TILE_SIZE));
        if tile_rows == 0 {
            return Err(EngineError::Invalid(format!(
                "a {w}-pixel-wide image needs {} bytes for one row of tiles, and this adapter \
                 binds at most {limit}: render a narrower image",
                RGBA_BYTES * u64::from(w) * u64::from(TILE_SIZE)
            )));
        }
        let most = u32::try_from(tile_rows * u64::from(TILE_SIZE)).unwrap_or(u32::MAX);
        // A stack, top band last, so bands finish top to bottom and append in order.
        let mut todo: Vec<(u32, u32)> = (0..h.div_ceil(most))
            .rev()
            .map(|b| (b * most, most.min(h - b * most)))
            .collect();
        let mut image = RenderedImage {
            width: w,
            height: h,
            color: frame_buffer(w, h, "colour")?,
            alpha: frame_buffer(w, h, "alpha")?,
            depth: frame_buffer(w, h, "depth")?,
        };
        let mut bands = 0;
        while let Some((first_row, rows)) = todo.pop() {
            let band = if rows == h {
                spec
            } else {
                spec.rows(first_row, rows)
            };
            batch.set_images(ctx, vec![band])?;
            let state = match self.forward_split(ctx, batch, false) {
                Err(EngineError::TooManyIntersections { .. }) if rows > TILE_SIZE => {
                    let top = (rows / 2).div_ceil(TILE_SIZE) * TILE_SIZE;
                    todo.push((first_row + top, rows - top));
                    todo.push((first_row, top));
                    continue;
                }
                other => other?,
            };
            let part = state
                .read_images(ctx, batch)?
                .pop()
                .ok_or_else(|| EngineError::Invalid("the renderer returned no image".into()))?;
            image.color.extend(part.color);
            image.alpha.extend(part.alpha);
            image.depth.extend(part.depth);
            bands += 1;
        }
        Ok(Frame { image, bands })
    }
}

/// Room for one value a pixel, or an error: a camera of absurd size (a typo in scene.json)
/// would otherwise abort the process on the allocation, leaving its scratch folders behind.
fn frame_buffer<T>(w: u32, h: u32, what: &str) -> Result<Vec<T>, EngineError> {
    let pixels = w as usize * h as usize;
    let mut v = Vec::new();
    v.try_reserve_exact(pixels).map_err(|_| {
        EngineError::Invalid(format!(
            "a {w}×{h} frame needs {:.1} GB of host memory for its {what} alone, which this \
             machine cannot allocate: check the camera's width and height",
            pixels as f64 * std::mem::size_of::<T>() as f64 / 1e9
        ))
    })?;
    Ok(v)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_frame_too_large_to_allocate_is_an_error_naming_its_size() {
        // Past isize::MAX bytes, so refused the same way on every machine, overcommit or not.
        let e = frame_buffer::<[f32; 3]>(u32::MAX, u32::MAX, "colour").unwrap_err();
        let said = e.to_string();
        assert!(
            said.contains("4294967295×4294967295") && said.contains("colour"),
            "{said}"
        );
        assert!(frame_buffer::<f32>(4, 3, "alpha").unwrap().capacity() >= 12);
    }
}
