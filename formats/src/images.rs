//! Training images: listing, sizes, loading as f32 RGB (8/16-bit, grey, RGBA) and downscaling.

use std::path::{Path, PathBuf};

use image::{DynamicImage, ImageReader, Rgba32FImage};

use crate::atomic::write_atomic;
use crate::error::{FormatError, Result};

/// Image files we read, compared case-insensitively.
const EXTENSIONS: [&str; 3] = ["png", "jpg", "jpeg"];

/// The image files directly in `dir`, sorted by file name (the order LLFF rows follow).
pub fn list_images(dir: &Path) -> Result<Vec<PathBuf>> {
    let entries = std::fs::read_dir(dir).map_err(|e| FormatError::io(dir, e))?;
    let mut out = Vec::new();
    for entry in entries {
        let p = entry.map_err(|e| FormatError::io(dir, e))?.path();
        let ext = p
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase);
        if p.is_file() && ext.is_some_and(|e| EXTENSIONS.contains(&e.as_str())) {
            out.push(p);
        }
    }
    out.sort_by(|a, b| a.file_name().cmp(&b.file_name()));
    Ok(out)
}

/// Width and height from the file header, without decoding pixels.
pub fn image_size(path: &Path) -> Result<(u32, u32)> {
    if !path.is_file() {
        let why = if path.is_dir() {
            "is a folder, expected an image file"
        } else {
            "file does not exist"
        };
        return Err(FormatError::invalid(path, "image", why));
    }
    image::image_dimensions(path)
        .map_err(|e| FormatError::invalid(path, "image", format!("cannot read image header: {e}")))
}

fn decode(path: &Path) -> Result<DynamicImage> {
    let bad = |e: String| FormatError::invalid(path, "image", e);
    ImageReader::open(path)
        .map_err(|e| FormatError::io(path, e))?
        .with_guessed_format()
        .map_err(|e| FormatError::io(path, e))?
        .decode()
        .map_err(|e| bad(format!("cannot decode: {e}")))
}

/// An RGB image with values in [0, 1] (sRGB-encoded, as stored), row-major, top row first.
#[derive(Debug, Clone, PartialEq)]
pub struct RgbImage {
    pub width: u32,
    pub height: u32,
    pub data: Vec<f32>,
}

/// Loads any supported image as RGB in [0, 1]. Grey is replicated to three channels; an alpha
/// channel is composited over `background` when given, else dropped.
pub fn load_rgb(path: &Path, background: Option<[f32; 3]>) -> Result<RgbImage> {
    let img = decode(path)?.into_rgba32f();
    let (width, height) = img.dimensions();
    let mut data = Vec::with_capacity(3 * (width * height) as usize);
    for p in img.pixels() {
        let [r, g, b, a] = p.0;
        match background {
            Some(bg) => data.extend([
                r * a + bg[0] * (1.0 - a),
                g * a + bg[1] * (1.0 - a),
                b * a + bg[2] * (1.0 - a),
            ]),
            None => data.extend([r, g, b]),
        }
    }
    Ok(RgbImage {
        width,
        height,
        data,
    })
}

/// Output size when shrinking by `factor`: rounded like INRIA's loader, at least 1 pixel.
pub fn downscaled_size(width: u32, height: u32, factor: u32) -> (u32, u32) {
    let f = f64::from(factor.max(1));
    (
        ((f64::from(width) / f).round() as u32).max(1),
        ((f64::from(height) / f).round() as u32).max(1),
    )
}

/// Area-averages `img` down to `downscaled_size`: each output pixel is the mean of the source
/// area it covers (exact box filter for integer factors, fractional coverage otherwise).
fn area_downscale(img: &Rgba32FImage, factor: u32) -> Rgba32FImage {
    let (w, h) = img.dimensions();
    let (ow, oh) = downscaled_size(w, h, factor);
    let (sx, sy) = (f64::from(w) / f64::from(ow), f64::from(h) / f64::from(oh));
    // Coverage of source index i by the output interval [a, b).
    let spans = |a: f64, b: f64| {
        let (lo, hi) = (
            a.floor() as u32,
            (b.ceil() as u32).max(a.floor() as u32 + 1),
        );
        (lo..hi).map(move |i| {
            (
                i,
                (b.min(f64::from(i) + 1.0) - a.max(f64::from(i))).max(0.0),
            )
        })
    };
    Rgba32FImage::from_fn(ow, oh, |x, y| {
        let mut acc = [0.0f64; 4];
        let mut total = 0.0;
        for (sy_i, wy) in spans(f64::from(y) * sy, f64::from(y + 1) * sy) {
            for (sx_i, wx) in spans(f64::from(x) * sx, f64::from(x + 1) * sx) {
                let wgt = wx * wy;
                if wgt > 0.0 && sx_i < w && sy_i < h {
                    let p = img.get_pixel(sx_i, sy_i).0;
                    for c in 0..4 {
                        acc[c] += wgt * f64::from(p[c]);
                    }
                    total += wgt;
                }
            }
        }
        image::Rgba(acc.map(|v| (v / total) as f32))
    })
}

/// Writes `src` shrunk by `factor` to `dst` as PNG, keeping its bit depth (8 or 16) and whether
/// it has colour and alpha. Atomic.
pub fn write_downscaled(src: &Path, dst: &Path, factor: u32) -> Result<(u32, u32)> {
    write_downscaled_over(src, dst, factor, None)
}

/// [`write_downscaled`], with a photo's alpha composited over `background` (0..1 in the
/// photo's own encoding, as the trainer's loader does) and dropped when one is given: scores must compare a render
/// over that colour with the photo over it.
pub fn write_downscaled_over(
    src: &Path,
    dst: &Path,
    factor: u32,
    background: Option<[f32; 3]>,
) -> Result<(u32, u32)> {
    let img = decode(src)?;
    let color = img.color();
    let mut small = area_downscale(&img.to_rgba32f(), factor);
    let alpha = match background {
        Some(bg) if color.has_alpha() => {
            for p in small.pixels_mut() {
                let a = p.0[3];
                for (v, b) in p.0.iter_mut().zip(bg) {
                    *v = *v * a + b * (1.0 - a);
                }
                p.0[3] = 1.0;
            }
            false
        }
        _ => color.has_alpha(),
    };
    let small = DynamicImage::ImageRgba32F(small);
    let sixteen = color.bytes_per_pixel() / color.channel_count() > 1;
    let out = match (sixteen, color.has_color(), alpha) {
        (false, true, true) => DynamicImage::ImageRgba8(small.to_rgba8()),
        (false, true, false) => DynamicImage::ImageRgb8(small.to_rgb8()),
        (false, false, true) => DynamicImage::ImageLumaA8(small.to_luma_alpha8()),
        (false, false, false) => DynamicImage::ImageLuma8(small.to_luma8()),
        (true, true, true) => DynamicImage::ImageRgba16(small.to_rgba16()),
        (true, true, false) => DynamicImage::ImageRgb16(small.to_rgb16()),
        (true, false, true) => DynamicImage::ImageLumaA16(small.to_luma_alpha16()),
        (true, false, false) => DynamicImage::ImageLuma16(small.to_luma16()),
    };
    write_atomic(dst, |w| {
        out.write_with_encoder(image::codecs::png::PngEncoder::new(w))
            .map_err(|e| FormatError::invalid(dst, "image", format!("cannot encode PNG: {e}")))
    })?;
    Ok((out.width(), out.height()))
}

/// LLFF-style pre-shrunk copy: `<dataset>/images_<factor>/<file name>` when it exists.
pub fn prescaled_path(dataset: &Path, image: &Path, factor: u32) -> Option<PathBuf> {
    if factor <= 1 {
        return None;
    }
    let p = dataset
        .join(format!("images_{factor}"))
        .join(image.file_name()?);
    p.is_file().then_some(p)
}
