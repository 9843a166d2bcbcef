//! GLB writer: one POINTS primitive, one tightly packed float bufferView per attribute.

use std::io::Write;
use std::path::Path;

use serde_json::{Value, json};

use super::{EXTENSION, FRAME_TAG, rotate_z180};
use crate::atomic::{io_at, write_atomic};
use crate::error::{FormatError, Result};
use crate::splats::{SH_C0, Splats, sigmoid};

const FLOAT: u32 = 5126;
const ARRAY_BUFFER: u32 = 34962;

fn srgb_to_linear(c: f32) -> f32 {
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

struct Builder {
    bin: Vec<u8>,
    views: Vec<Value>,
    accessors: Vec<Value>,
}

impl Builder {
    /// Appends one attribute; returns its accessor index.
    fn push(&mut self, ty: &str, width: usize, data: &[f32], min_max: bool) -> usize {
        let offset = self.bin.len();
        for v in data {
            self.bin.extend_from_slice(&v.to_le_bytes());
        }
        self.views.push(json!({"buffer": 0, "byteOffset": offset, "byteLength": data.len() * 4, "target": ARRAY_BUFFER}));
        let mut acc = json!({"bufferView": self.views.len() - 1, "componentType": FLOAT, "count": data.len() / width, "type": ty});
        if min_max {
            let mut lo = vec![f32::INFINITY; width];
            let mut hi = vec![f32::NEG_INFINITY; width];
            for chunk in data.chunks_exact(width) {
                for (k, v) in chunk.iter().enumerate() {
                    lo[k] = lo[k].min(*v);
                    hi[k] = hi[k].max(*v);
                }
            }
            acc["min"] = json!(lo);
            acc["max"] = json!(hi);
        }
        self.accessors.push(acc);
        self.accessors.len() - 1
    }
}

/// Writes `splats` as a `.glb` with `KHR_gaussian_splatting`, atomically. Non-finite values are
/// refused: glTF accessors must not hold NaN.
pub fn write_glb(path: &Path, splats: &Splats) -> Result<()> {
    splats.check_writable(path)?;
    if splats.is_empty() {
        return Err(FormatError::invalid(
            path,
            "splats",
            "no splats to write (glTF accessors need count ≥ 1)",
        ));
    }
    let mut s = splats.clone();
    rotate_z180(&mut s, false);
    let n = s.len();
    let k = s.rest_per_channel();
    let mut b = Builder {
        bin: Vec::new(),
        views: Vec::new(),
        accessors: Vec::new(),
    };
    let mut attributes = serde_json::Map::new();
    attributes.insert("POSITION".into(), json!(b.push("VEC3", 3, &s.means, true)));
    let rot: Vec<f32> = s
        .rotations
        .chunks_exact(4)
        .flat_map(|q| {
            let len = q.iter().map(|v| v * v).sum::<f32>().sqrt();
            let (w, x, y, z) = if len > 0.0 {
                (q[0] / len, q[1] / len, q[2] / len, q[3] / len)
            } else {
                (1.0, 0.0, 0.0, 0.0)
            };
            [x, y, z, w]
        })
        .collect();
    let alpha: Vec<f32> = s.opacities.iter().map(|v| sigmoid(*v)).collect();
    let color: Vec<f32> = (0..n)
        .flat_map(|i| {
            let c = |ch: usize| srgb_to_linear((0.5 + SH_C0 * s.sh_dc[3 * i + ch]).clamp(0.0, 1.0));
            [c(0), c(1), c(2), alpha[i]]
        })
        .collect();
    attributes.insert("COLOR_0".into(), json!(b.push("VEC4", 4, &color, false)));
    attributes.insert(
        format!("{EXTENSION}:ROTATION"),
        json!(b.push("VEC4", 4, &rot, false)),
    );
    let scale: Vec<f32> = s.log_scales.iter().map(|v| v.exp()).collect();
    attributes.insert(
        format!("{EXTENSION}:SCALE"),
        json!(b.push("VEC3", 3, &scale, false)),
    );
    attributes.insert(
        format!("{EXTENSION}:OPACITY"),
        json!(b.push("SCALAR", 1, &alpha, false)),
    );
    attributes.insert(
        format!("{EXTENSION}:SH_DEGREE_0_COEF_0"),
        json!(b.push("VEC3", 3, &s.sh_dc, false)),
    );
    for l in 1..=s.sh_degree as usize {
        for m in 0..2 * l + 1 {
            let j = l * l - 1 + m;
            let coef: Vec<f32> = (0..n)
                .flat_map(|i| (0..3).map(move |c| (i, c)))
                .map(|(i, c)| s.sh_rest[3 * k * i + c * k + j])
                .collect();
            attributes.insert(
                format!("{EXTENSION}:SH_DEGREE_{l}_COEF_{m}"),
                json!(b.push("VEC3", 3, &coef, false)),
            );
        }
    }
    let doc = json!({
        "asset": {"version": "2.0", "generator": "cocog", "extras": {"cocog_frame": FRAME_TAG}},
        "extensionsUsed": [EXTENSION],
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{
            "mode": 0,
            "attributes": attributes,
            "extensions": {EXTENSION: {"kernel": "ellipse", "colorSpace": "srgb_rec709_display", "projection": "perspective", "sortingMethod": "cameraDistance"}}
        }]}],
        "buffers": [{"byteLength": b.bin.len()}],
        "bufferViews": b.views,
        "accessors": b.accessors,
    });
    let mut json_bytes =
        serde_json::to_vec(&doc).map_err(|e| FormatError::invalid(path, "json", e.to_string()))?;
    while !json_bytes.len().is_multiple_of(4) {
        json_bytes.push(b' ');
    }
    let mut bin = b.bin;
    while !bin.len().is_multiple_of(4) {
        bin.push(0);
    }
    let total = 12 + 8 + json_bytes.len() + 8 + bin.len();
    let total = u32::try_from(total).map_err(|_| {
        FormatError::invalid(
            path,
            "size",
            format!("{total} bytes exceeds the 4 GiB GLB limit"),
        )
    })?;
    write_atomic(path, |w| {
        let mut put = |b: &[u8]| w.write_all(b).map_err(io_at(path));
        put(b"glTF")?;
        put(&2u32.to_le_bytes())?;
        put(&total.to_le_bytes())?;
        put(&(json_bytes.len() as u32).to_le_bytes())?;
        put(b"JSON")?;
        put(&json_bytes)?;
        put(&(bin.len() as u32).to_le_bytes())?;
        put(b"BIN\0")?;
        put(&bin)
    })
}
