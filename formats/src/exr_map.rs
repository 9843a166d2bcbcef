//! Single-channel f32 maps (depth and the like) in OpenEXR.
//!
//! We write one FLOAT channel named `Y`, ZIP-compressed: OpenCV, imageio and nerfstudio read that
//! as a grey image. Reading accepts `Y`, `Z`, `R`, `depth`, or else the file's only channel.

use std::io::Cursor;
use std::path::Path;

use exr::prelude::{
    Encoding, FlatSamples, Image, ReadChannels, ReadLayers, SpecificChannels, Vec2, WritableImage,
    read,
};

use crate::atomic::write_atomic;
use crate::error::{FormatError, Result, read_file};

/// A row-major `width`×`height` map, top row first.
#[derive(Debug, Clone, PartialEq)]
pub struct FloatMap {
    pub width: usize,
    pub height: usize,
    pub data: Vec<f32>,
}

/// Channel names tried in order when reading.
const PREFERRED: [&str; 4] = ["Y", "Z", "R", "depth"];

/// Writes `map` as a single-channel float EXR with channel `Y`, atomically.
pub fn write_exr(path: &Path, map: &FloatMap) -> Result<()> {
    if map.width == 0 || map.height == 0 || map.data.len() != map.width * map.height {
        return Err(FormatError::invalid(
            path,
            "map",
            format!(
                "{} values for a {}×{} map",
                map.data.len(),
                map.width,
                map.height
            ),
        ));
    }
    let channels = SpecificChannels::build()
        .with_channel("Y")
        .with_pixel_fn(|p: Vec2<usize>| (map.data[p.y() * map.width + p.x()],));
    let image =
        Image::from_encoded_channels((map.width, map.height), Encoding::SMALL_LOSSLESS, channels);
    write_atomic(path, |w| {
        image
            .write()
            .to_buffered(w)
            .map_err(|e| FormatError::invalid(path, "exr", format!("cannot encode: {e}")))
    })
}

/// Reads the depth-like channel of a single-layer EXR as f32 (half and uint samples converted).
pub fn read_exr(path: &Path) -> Result<FloatMap> {
    let bytes = read_file(path)?;
    let image = read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .first_valid_layer()
        .all_attributes()
        .from_buffered(Cursor::new(bytes))
        .map_err(|e| {
            FormatError::invalid(path, "exr", format!("not a readable OpenEXR image: {e}"))
        })?;
    let layer = &image.layer_data;
    let list = &layer.channel_data.list;
    let names: Vec<String> = list.iter().map(|c| c.name.to_string()).collect();
    let pick = PREFERRED
        .iter()
        .find_map(|want| names.iter().position(|n| n == want))
        .or((list.len() == 1).then_some(0))
        .ok_or_else(|| {
            FormatError::invalid(path, "channels", format!("expected a channel named Y, Z, R or depth (or a single channel), found {names:?}"))
        })?;
    let data: Vec<f32> = match &list[pick].sample_data {
        FlatSamples::F32(v) => v.clone(),
        other => other.values_as_f32().collect(),
    };
    let (width, height) = (layer.size.width(), layer.size.height());
    if data.len() != width * height {
        return Err(FormatError::invalid(
            path,
            "channels",
            format!(
                "channel has {} samples for {width}×{height} (subsampled channels are not supported)",
                data.len()
            ),
        ));
    }
    Ok(FloatMap {
        width,
        height,
        data,
    })
}
