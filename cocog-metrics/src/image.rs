//! Decoding PNG/JPEG into the [0,1] RGB arrays the metrics work on.
//!
//! Policy (the papers only ever score 8-bit RGB, so everything else is mapped onto that exactly or
//! refused):
//! - 8-bit: value / 255, no gamma conversion (the Deblur-NeRF convention).
//! - 16-bit: value / 65535, exact.
//! - grayscale: replicated to three channels, so SSIM equals the single-channel SSIM and LPIPS sees
//!   a neutral gray image.
//! - alpha: accepted only when every pixel is fully opaque (the alpha is then dropped); any
//!   translucent pixel is refused, because compositing on an arbitrary background would silently
//!   change the score.
//! - float images: refused (not produced by PNG/JPEG).

use std::path::Path;

use image::DynamicImage;

use crate::MetricsError;

/// An RGB image with values in [0,1], interleaved row-major (`data[(y*width+x)*3+c]`).
#[derive(Debug, Clone, PartialEq)]
pub struct FloatImage {
    pub width: u32,
    pub height: u32,
    pub data: Vec<f64>,
}

impl FloatImage {
    /// Wraps interleaved 8-bit RGB data. Panics only on a length that contradicts the size, which
    /// is a programming error, not bad input.
    pub fn from_rgb8(width: u32, height: u32, rgb: &[u8]) -> Self {
        assert_eq!(
            rgb.len(),
            width as usize * height as usize * 3,
            "rgb8 length"
        );
        let data = rgb.iter().map(|&v| f64::from(v) / 255.0).collect();
        Self {
            width,
            height,
            data,
        }
    }

    /// One channel as a contiguous plane, mapped by `f` (used to put SSIM inputs on [−1,1]).
    pub(crate) fn plane(&self, channel: usize, f: impl Fn(f64) -> f64) -> Vec<f64> {
        self.data
            .iter()
            .skip(channel)
            .step_by(3)
            .map(|&v| f(v))
            .collect()
    }
}

/// Reads and decodes `path` (format from its content, not its name) under the policy above.
pub fn load_image(path: &Path) -> Result<FloatImage, MetricsError> {
    let io_err = |source| MetricsError::Io {
        path: path.to_path_buf(),
        source,
    };
    let decoded = image::ImageReader::open(path)
        .map_err(io_err)?
        .with_guessed_format()
        .map_err(io_err)?
        .decode()
        .map_err(|source| MetricsError::Decode {
            path: path.to_path_buf(),
            source,
        })?;
    from_dynamic(path, decoded)
}

fn from_dynamic(path: &Path, img: DynamicImage) -> Result<FloatImage, MetricsError> {
    let (width, height) = (img.width(), img.height());
    let unsupported = |reason: String| MetricsError::Unsupported {
        path: path.to_path_buf(),
        reason,
    };
    let data: Vec<f64> = match img {
        DynamicImage::ImageRgb8(b) => scale(b.as_raw(), 3, 255.0),
        DynamicImage::ImageLuma8(b) => scale(b.as_raw(), 1, 255.0),
        DynamicImage::ImageRgb16(b) => scale(b.as_raw(), 3, 65535.0),
        DynamicImage::ImageLuma16(b) => scale(b.as_raw(), 1, 65535.0),
        DynamicImage::ImageRgba8(b) => opaque(b.as_raw(), 3, 255.0).map_err(unsupported)?,
        DynamicImage::ImageLumaA8(b) => opaque(b.as_raw(), 1, 255.0).map_err(unsupported)?,
        DynamicImage::ImageRgba16(b) => opaque(b.as_raw(), 3, 65535.0).map_err(unsupported)?,
        DynamicImage::ImageLumaA16(b) => opaque(b.as_raw(), 1, 65535.0).map_err(unsupported)?,
        other => {
            return Err(unsupported(format!(
                "pixel format {:?}: expected 8- or 16-bit gray or RGB",
                other.color()
            )));
        }
    };
    Ok(FloatImage {
        width,
        height,
        data,
    })
}

/// Maps `colors`-channel samples (1 or 3) to interleaved RGB on [0,1].
fn scale<T: Copy + Into<f64>>(raw: &[T], colors: usize, max: f64) -> Vec<f64> {
    let mut out = Vec::with_capacity(raw.len() / colors * 3);
    for px in raw.chunks_exact(colors) {
        for c in 0..3 {
            out.push(px[c % colors].into() / max);
        }
    }
    out
}

/// Like [`scale`] for samples followed by an alpha channel, refusing any pixel that is not fully
/// opaque.
fn opaque<T: Copy + Into<f64>>(raw: &[T], colors: usize, max: f64) -> Result<Vec<f64>, String> {
    let stride = colors + 1;
    let translucent = raw
        .chunks_exact(stride)
        .filter(|px| px[colors].into() != max)
        .count();
    if translucent > 0 {
        return Err(format!(
            "alpha channel has {translucent} pixel(s) that are not fully opaque; \
             composite the image onto the background you mean before scoring"
        ));
    }
    let mut colour = Vec::with_capacity(raw.len() / stride * colors);
    for px in raw.chunks_exact(stride) {
        colour.extend_from_slice(&px[..colors]);
    }
    Ok(scale(&colour, colors, max))
}

#[cfg(test)]
mod tests {
    use super::*;
    use image::{GrayImage, ImageBuffer, Luma, Rgb, Rgba};

    fn write_and_load<P: image::Pixel<Subpixel = S> + image::PixelWithColorType, S>(
        img: ImageBuffer<P, Vec<S>>,
    ) -> Result<FloatImage, MetricsError>
    where
        S: image::Primitive,
        [S]: image::EncodableLayout,
    {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("x.png");
        img.save(&path).unwrap();
        load_image(&path)
    }

    #[test]
    fn gray8_is_replicated() {
        let img = GrayImage::from_fn(3, 2, |x, y| Luma([(x * 40 + y * 7) as u8]));
        let f = write_and_load(img).unwrap();
        assert_eq!((f.width, f.height), (3, 2));
        assert_eq!(f.data.len(), 18);
        // Pixel (2,1) = 87.
        let i = (3 + 2) * 3;
        assert_eq!(&f.data[i..i + 3], &[87.0 / 255.0; 3]);
    }

    #[test]
    fn rgb16_is_divided_by_65535_exactly() {
        let img = ImageBuffer::<Rgb<u16>, _>::from_fn(2, 2, |x, y| {
            Rgb([x as u16 * 65535, 257 * y as u16, 12345])
        });
        let f = write_and_load(img).unwrap();
        assert_eq!(&f.data[3..6], &[1.0, 0.0, 12345.0 / 65535.0]);
        assert_eq!(&f.data[6..9], &[0.0, 257.0 / 65535.0, 12345.0 / 65535.0]);
    }

    #[test]
    fn opaque_rgba_is_accepted_translucent_refused() {
        let ok = ImageBuffer::<Rgba<u8>, _>::from_fn(2, 2, |x, _| Rgba([x as u8, 2, 3, 255]));
        let f = write_and_load(ok).unwrap();
        assert_eq!(&f.data[3..6], &[1.0 / 255.0, 2.0 / 255.0, 3.0 / 255.0]);

        let bad = ImageBuffer::<Rgba<u8>, _>::from_fn(2, 2, |x, y| {
            Rgba([0, 0, 0, if x == 1 && y == 1 { 128 } else { 255 }])
        });
        let err = write_and_load(bad).unwrap_err().to_string();
        assert!(err.contains("x.png"), "{err}");
        assert!(err.contains("1 pixel(s)"), "{err}");
    }

    #[test]
    fn garbage_is_a_decode_error_naming_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("broken.png");
        std::fs::write(&path, b"\x89PNG\r\n\x1a\nnot really").unwrap();
        let err = load_image(&path).unwrap_err();
        assert!(matches!(err, MetricsError::Decode { .. }), "{err:?}");
        assert!(err.to_string().contains("broken.png"));
    }
}
