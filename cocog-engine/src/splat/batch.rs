//! Parameters and cameras of a batch of images, resident on the GPU.

use crate::EngineError;
use crate::core::{GpuBuffer, GpuContext, Workspace};
use crate::error::mib;
use crate::types::{Camera, GaussianGrads, GaussianParams, View, sh_coeffs_per_channel};

/// GPU layout of one image's camera (see `ImageInfo` in project_common.wgsl).
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
pub(crate) struct ImageInfo {
    rows: [[f32; 4]; 3],
    centre: [f32; 4],
    intrinsics: [f32; 4],
    background: [f32; 4],
    first: u32,
    count: u32,
    /// cy and height of the whole frame, whose edges bound the projection's clamp.
    frame: [f32; 2],
}

/// Gaussian parameters of all images of a batch, concatenated in image order, one buffer per
/// `GaussianParams` field (same layout). Gradients use the same type.
#[derive(Debug)]
pub struct ParamBuffers {
    pub means: GpuBuffer,
    pub log_scales: GpuBuffer,
    pub quats: GpuBuffer,
    pub opacity_logits: GpuBuffer,
    pub sh: GpuBuffer,
    pub sh_degree: u32,
    pub num_gaussians: u32,
    /// 0: every buffer has `num_gaussians` rows. k > 0: `opacity_logits` and `sh` have k
    /// rows and Gaussian g reads row g mod k, so sets of k Gaussians (CoCoGaussian's copies,
    /// method.md §3.5) share them instead of holding copies. Gradients keep one row per
    /// Gaussian.
    pub shared_rows: u32,
}

/// Bytes per Gaussian of the engine's widest per-Gaussian buffer: the SH coefficients, or the
/// 48-byte projected record at low degrees.
pub fn bytes_per_gaussian(sh_degree: u32) -> u64 {
    (12 * sh_coeffs_per_channel(sh_degree) as u64).max(48)
}

/// Refuses `gaussians` whose widest buffer would exceed a buffer binding of `limit` bytes,
/// which wgpu would otherwise report as a validation panic when the buffer is bound.
pub fn check_fits(limit: u64, gaussians: u64, sh_degree: u32) -> Result<(), EngineError> {
    check_fits_at(limit, gaussians, bytes_per_gaussian(sh_degree), sh_degree)
}

/// [`check_fits`] for a caller whose widest buffer holds `per` bytes a Gaussian (a trainer
/// binding several rows per Gaussian).
pub fn check_fits_at(
    limit: u64,
    gaussians: u64,
    per: u64,
    sh_degree: u32,
) -> Result<(), EngineError> {
    if gaussians * per <= limit {
        return Ok(());
    }
    Err(EngineError::TooManyGaussians {
        gaussians,
        sh_degree,
        most: limit / per,
        needed_mib: mib(gaussians * per),
        limit_mib: mib(limit),
    })
}

impl ParamBuffers {
    /// Uploads `sets` back to back.
    pub fn upload(ctx: &GpuContext, sets: &[&GaussianParams]) -> Result<Self, EngineError> {
        let sh_degree = sets.first().map_or(0, |s| s.sh_degree);
        let total: u64 = sets.iter().map(|s| s.len() as u64).sum();
        check_fits(ctx.binding_limit(), total, sh_degree)?;
        let mut all = GaussianParams {
            sh_degree,
            ..Default::default()
        };
        for s in sets {
            s.validate()?;
            if s.sh_degree != sh_degree {
                return Err(EngineError::Invalid(
                    "all Gaussian sets of a batch must share one SH degree".into(),
                ));
            }
            all.means.extend_from_slice(&s.means);
            all.log_scales.extend_from_slice(&s.log_scales);
            all.quats.extend_from_slice(&s.quats);
            all.opacity_logits.extend_from_slice(&s.opacity_logits);
            all.sh.extend_from_slice(&s.sh);
        }
        let num_gaussians = u32::try_from(all.len())
            .map_err(|_| EngineError::Invalid("too many Gaussians".into()))?;
        Ok(Self {
            means: ctx.storage_from("means", &all.means),
            log_scales: ctx.storage_from("log_scales", &all.log_scales),
            quats: ctx.storage_from("quats", &all.quats),
            opacity_logits: ctx.storage_from("opacity_logits", &all.opacity_logits),
            sh: ctx.storage_from("sh", &all.sh),
            sh_degree,
            num_gaussians,
            shared_rows: 0,
        })
    }

    /// Zeroed buffers shaped like `self`.
    pub fn zeros_like(ctx: &GpuContext, like: &Self) -> Self {
        let n = u64::from(like.num_gaussians);
        let sh_floats = n * 3 * sh_coeffs_per_channel(like.sh_degree) as u64;
        Self {
            means: ctx.storage("v_means", n * 12),
            log_scales: ctx.storage("v_log_scales", n * 12),
            quats: ctx.storage("v_quats", n * 16),
            opacity_logits: ctx.storage("v_opacity_logits", n * 4),
            sh: ctx.storage("v_sh", sh_floats * 4),
            sh_degree: like.sh_degree,
            num_gaussians: like.num_gaussians,
            shared_rows: 0,
        }
    }

    /// Gradient buffers shaped like `like`, from `ws` (the backward writes every element, so
    /// they need no clearing).
    pub fn gradients_in(ctx: &GpuContext, ws: &mut Workspace, like: &Self) -> Self {
        let n = u64::from(like.num_gaussians);
        let sh_floats = n * 3 * sh_coeffs_per_channel(like.sh_degree) as u64;
        Self {
            means: ws.buffer(ctx, "v_means", n * 12),
            log_scales: ws.buffer(ctx, "v_log_scales", n * 12),
            quats: ws.buffer(ctx, "v_quats", n * 16),
            opacity_logits: ws.buffer(ctx, "v_opacity_logits", n * 4),
            sh: ws.buffer(ctx, "v_sh", sh_floats * 4),
            sh_degree: like.sh_degree,
            num_gaussians: like.num_gaussians,
            shared_rows: 0,
        }
    }

    /// Reads Gaussians `[first, first + count)` back as gradients (one GPU→CPU sync per field).
    pub fn read_grads(
        &self,
        ctx: &GpuContext,
        first: u32,
        count: u32,
    ) -> Result<GaussianGrads, EngineError> {
        if self.shared_rows != 0 {
            return Err(EngineError::Invalid(
                "read_grads reads one row per Gaussian; these buffers share rows".into(),
            ));
        }
        let total = self.num_gaussians as usize;
        let (a, b) = (first as usize, (first + count) as usize);
        if b > total {
            return Err(EngineError::Invalid(format!(
                "range {a}..{b} exceeds {total} Gaussians"
            )));
        }
        let stride = 3 * sh_coeffs_per_channel(self.sh_degree);
        let means: Vec<[f32; 3]> = ctx.read(&self.means, total)?;
        let scales: Vec<[f32; 3]> = ctx.read(&self.log_scales, total)?;
        let quats: Vec<[f32; 4]> = ctx.read(&self.quats, total)?;
        let opac: Vec<f32> = ctx.read(&self.opacity_logits, total)?;
        let sh: Vec<f32> = ctx.read(&self.sh, total * stride)?;
        Ok(GaussianGrads {
            v_means: means[a..b].to_vec(),
            v_log_scales: scales[a..b].to_vec(),
            v_quats: quats[a..b].to_vec(),
            v_opacity_logits: opac[a..b].to_vec(),
            v_sh: sh[a * stride..b * stride].to_vec(),
        })
    }
}

/// One image of a batch: which Gaussians it renders, seen from where, over what.
#[derive(Clone, Copy, Debug)]
pub struct ImageSpec {
    pub camera: Camera,
    pub background: [f32; 3],
    pub first: u32,
    pub count: u32,
    /// `Some` when `camera` sees a band of rows cut from a taller frame (`ImageSpec::rows`).
    pub crop: Option<Crop>,
}

/// Where a band of rows sits in the frame it was cut from. The projection clamps each
/// footprint's centre against the frame's edges, not the band's, so that bands rendered one
/// by one give the pixels of the whole frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Crop {
    pub first_row: u32,
    pub frame_height: u32,
}

impl ImageSpec {
    /// Rows `first_row..first_row + rows` of this image, as an image of their own.
    pub fn rows(&self, first_row: u32, rows: u32) -> ImageSpec {
        let outer = self.crop.unwrap_or(Crop {
            first_row: 0,
            frame_height: self.camera.height,
        });
        let mut camera = self.camera;
        camera.cy -= f64::from(first_row);
        camera.height = rows;
        ImageSpec {
            camera,
            crop: Some(Crop {
                first_row: outer.first_row + first_row,
                frame_height: outer.frame_height,
            }),
            ..*self
        }
    }

    /// (cy, height) of the whole frame this image belongs to.
    fn frame(&self) -> Result<(f64, u32), EngineError> {
        let cam = &self.camera;
        match self.crop {
            None => Ok((cam.cy, cam.height)),
            Some(c)
                if u64::from(c.first_row) + u64::from(cam.height) <= u64::from(c.frame_height) =>
            {
                Ok((cam.cy + f64::from(c.first_row), c.frame_height))
            }
            Some(c) => Err(EngineError::Invalid(format!(
                "a band of rows {}..{} does not fit its frame of {} rows",
                c.first_row,
                u64::from(c.first_row) + u64::from(cam.height),
                c.frame_height
            ))),
        }
    }
}

/// The GPU records of `images`, checked against each other and against `params`.
fn image_infos(params: &ParamBuffers, images: &[ImageSpec]) -> Result<Vec<ImageInfo>, EngineError> {
    let first = images
        .first()
        .ok_or_else(|| EngineError::Invalid("a batch needs at least one image".into()))?;
    let (w, h) = (first.camera.width, first.camera.height);
    if w == 0 || h == 0 || w > 65_535 * 16 || h > 65_535 * 16 {
        return Err(EngineError::Invalid(format!(
            "unsupported image size {w}×{h}"
        )));
    }
    let shared = params.shared_rows;
    if shared > 0 && !params.num_gaussians.is_multiple_of(shared) {
        return Err(EngineError::Invalid(format!(
            "{} Gaussians cannot share opacity and SH rows in sets of {shared}",
            params.num_gaussians
        )));
    }
    let mut infos = Vec::with_capacity(images.len());
    for im in images {
        if (im.camera.width, im.camera.height) != (w, h) {
            return Err(EngineError::Invalid(
                "all images of a batch must share one resolution".into(),
            ));
        }
        if u64::from(im.first) + u64::from(im.count) > u64::from(params.num_gaussians) {
            return Err(EngineError::Invalid(
                "image Gaussian range exceeds the parameters".into(),
            ));
        }
        let (frame_cy, frame_height) = im.frame()?;
        let (r, t) = im.camera.camera_from_world();
        let c = im.camera.centre();
        let cam = &im.camera;
        infos.push(ImageInfo {
            rows: std::array::from_fn(|i| {
                [r[i][0] as f32, r[i][1] as f32, r[i][2] as f32, t[i] as f32]
            }),
            centre: [c[0] as f32, c[1] as f32, c[2] as f32, 0.0],
            intrinsics: [cam.fx as f32, cam.fy as f32, cam.cx as f32, cam.cy as f32],
            background: [im.background[0], im.background[1], im.background[2], 0.0],
            first: im.first,
            count: im.count,
            frame: [frame_cy as f32, frame_height as f32],
        });
    }
    Ok(infos)
}

/// Everything a forward pass needs: parameters plus per-image cameras. All images share one
/// resolution, and each renders its own contiguous range of Gaussians.
#[derive(Debug)]
pub struct Batch {
    pub params: ParamBuffers,
    pub images: Vec<ImageSpec>,
    pub(crate) image_infos: GpuBuffer,
    pub(crate) backgrounds: GpuBuffer,
}

impl Batch {
    pub fn new(
        ctx: &GpuContext,
        params: ParamBuffers,
        images: Vec<ImageSpec>,
    ) -> Result<Self, EngineError> {
        let infos = image_infos(&params, &images)?;
        let backgrounds: Vec<[f32; 4]> = infos.iter().map(|i| i.background).collect();
        Ok(Self {
            image_infos: ctx.storage_from("image infos", &infos),
            backgrounds: ctx.storage_from("backgrounds", &backgrounds),
            params,
            images,
        })
    }

    /// Points the batch at other cameras, backgrounds or Gaussian ranges. Writes into the
    /// existing buffers (queued before the next submission) when the image count allows, so
    /// a training loop re-aims one batch every step without allocating.
    pub fn set_images(
        &mut self,
        ctx: &GpuContext,
        images: Vec<ImageSpec>,
    ) -> Result<(), EngineError> {
        let infos = image_infos(&self.params, &images)?;
        let backgrounds: Vec<[f32; 4]> = infos.iter().map(|i| i.background).collect();
        let fits = std::mem::size_of_val(infos.as_slice()) as u64 <= self.image_infos.size();
        if fits {
            ctx.queue
                .write_buffer(&self.image_infos, 0, bytemuck::cast_slice(&infos));
            ctx.queue
                .write_buffer(&self.backgrounds, 0, bytemuck::cast_slice(&backgrounds));
        } else {
            self.image_infos = ctx.storage_from("image infos", &infos);
            self.backgrounds = ctx.storage_from("backgrounds", &backgrounds);
        }
        self.images = images;
        Ok(())
    }

    /// Uploads the views' Gaussians back to back and makes one image per view.
    pub fn from_views(ctx: &GpuContext, views: &[View<'_>]) -> Result<Self, EngineError> {
        let sets: Vec<&GaussianParams> = views.iter().map(|v| v.gaussians).collect();
        let params = ParamBuffers::upload(ctx, &sets)?;
        let mut first = 0u32;
        let images = views
            .iter()
            .map(|v| {
                let count = v.gaussians.len() as u32;
                let spec = ImageSpec {
                    camera: *v.camera,
                    background: v.background,
                    first,
                    count,
                    crop: None,
                };
                first += count;
                spec
            })
            .collect();
        Self::new(ctx, params, images)
    }

    pub fn width(&self) -> u32 {
        self.images[0].camera.width
    }

    pub fn height(&self) -> u32 {
        self.images[0].camera.height
    }

    pub fn tiles(&self) -> (u32, u32) {
        self.images[0].camera.tiles()
    }

    pub fn num_images(&self) -> u32 {
        self.images.len() as u32
    }

    pub(crate) fn num_pixels(&self) -> u64 {
        u64::from(self.width()) * u64::from(self.height()) * u64::from(self.num_images())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_set_past_the_binding_is_refused_by_count() {
        let limit = 128 << 20;
        // SH 3: 48 coefficients × 4 bytes per Gaussian.
        assert_eq!(bytes_per_gaussian(3), 192);
        assert_eq!(bytes_per_gaussian(0), 48);
        assert!(check_fits(limit, 699_050, 3).is_ok());
        let e = check_fits(limit, 1_000_000, 3).unwrap_err().to_string();
        assert!(
            e.contains("1000000 Gaussians at SH degree 3 need 183 MiB")
                && e.contains("at most 699050 Gaussians fit"),
            "{e}"
        );
        assert!(check_fits(limit, 1_000_000, 0).is_ok());
    }
}
