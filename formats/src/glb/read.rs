//! GLB reader for `KHR_gaussian_splatting` primitives (float or normalized integer accessors).

use std::path::Path;

use serde_json::Value;

use super::{EXTENSION, rotate_z180};
use crate::bytes::ByteReader;
use crate::error::{FormatError, Result, read_file};
use crate::splats::{Splats, logit};

/// The GLB container: JSON document and BIN chunk.
fn split_chunks(path: &Path, data: &[u8]) -> Result<(Value, Vec<u8>)> {
    let mut r = ByteReader::new(path, data);
    let magic = r.take(4, &|| "magic".into())?;
    if magic != b"glTF" {
        return Err(FormatError::invalid(
            path,
            "magic",
            format!("expected \"glTF\", got {magic:?}"),
        ));
    }
    let version = r.u32(&|| "version".into())?;
    if version != 2 {
        return Err(FormatError::invalid(
            path,
            "version",
            format!("expected GLB version 2, got {version}"),
        ));
    }
    let total = r.u32(&|| "length".into())? as usize;
    if total != data.len() {
        return Err(FormatError::invalid(
            path,
            "length",
            format!("header says {total} bytes, file has {}", data.len()),
        ));
    }
    let mut json = None;
    let mut bin = Vec::new();
    while r.remaining() > 0 {
        let len = r.u32(&|| "chunk length".into())? as usize;
        let kind = r.u32(&|| "chunk type".into())?;
        let body = r.take(len, &|| format!("chunk {kind:#x} body"))?;
        match kind {
            0x4E4F_534A if json.is_none() => {
                json = Some(
                    serde_json::from_slice(body)
                        .map_err(|e| FormatError::invalid(path, "JSON chunk", e.to_string()))?,
                );
            }
            0x004E_4942 if bin.is_empty() => bin = body.to_vec(),
            _ => {}
        }
    }
    let json = json.ok_or_else(|| FormatError::invalid(path, "JSON chunk", "missing"))?;
    Ok((json, bin))
}

struct Doc<'a> {
    path: &'a Path,
    json: &'a Value,
    bin: &'a [u8],
}

impl Doc<'_> {
    /// Reads accessor `index` as f32 values (`width` per element), normalizing integer types.
    fn accessor(&self, index: &Value, width: usize, what: &str) -> Result<Vec<f32>> {
        let bad = |msg: String| FormatError::invalid(self.path, format!("attribute {what}"), msg);
        let i = index
            .as_u64()
            .ok_or_else(|| bad("accessor index is not an integer".into()))?
            as usize;
        let acc = &self.json["accessors"][i];
        let count = acc["count"]
            .as_u64()
            .ok_or_else(|| bad(format!("accessor {i} has no count")))? as usize;
        let comps = match acc["type"].as_str() {
            Some("SCALAR") => 1,
            Some("VEC3") => 3,
            Some("VEC4") => 4,
            other => {
                return Err(bad(format!(
                    "accessor {i} type {other:?} is not SCALAR/VEC3/VEC4"
                )));
            }
        };
        if comps != width {
            return Err(bad(format!(
                "accessor {i} has {comps} components, expected {width}"
            )));
        }
        let ctype = acc["componentType"].as_u64().unwrap_or(0);
        let normalized = acc["normalized"].as_bool().unwrap_or(false);
        let size = match (ctype, normalized) {
            (5126, _) => 4,
            (5120 | 5121, true) => 1,
            (5122 | 5123, true) => 2,
            _ => {
                return Err(bad(format!(
                    "accessor {i} componentType {ctype} (normalized {normalized}) is not float or a normalized integer"
                )));
            }
        };
        let view = &self.json["bufferViews"][acc["bufferView"].as_u64().ok_or_else(|| {
            bad(format!(
                "accessor {i} has no bufferView (sparse/compressed data is not supported)"
            ))
        })? as usize];
        if view["buffer"].as_u64() != Some(0) {
            return Err(bad("only the GLB's own buffer 0 is supported".into()));
        }
        let start = view["byteOffset"].as_u64().unwrap_or(0) as usize
            + acc["byteOffset"].as_u64().unwrap_or(0) as usize;
        let stride = view["byteStride"]
            .as_u64()
            .map_or(size * comps, |s| s as usize);
        let end = count.checked_sub(1).map_or(Some(start), |c| {
            c.checked_mul(stride)
                .and_then(|o| o.checked_add(start + size * comps))
        });
        let view_end = view["byteOffset"].as_u64().unwrap_or(0) as usize
            + view["byteLength"].as_u64().unwrap_or(0) as usize;
        match end {
            Some(e) if e <= view_end && view_end <= self.bin.len() && stride >= size * comps => {}
            _ => {
                return Err(bad(format!(
                    "accessor {i} ({count} × {comps}) runs past its bufferView or the BIN chunk"
                )));
            }
        }
        let mut out = Vec::with_capacity(count * comps);
        for e in 0..count {
            for c in 0..comps {
                let o = start + e * stride + c * size;
                let b = &self.bin[o..o + size];
                out.push(match ctype {
                    5126 => f32::from_le_bytes([b[0], b[1], b[2], b[3]]),
                    5121 => f32::from(b[0]) / 255.0,
                    5120 => (f32::from(b[0] as i8) / 127.0).max(-1.0),
                    5123 => f32::from(u16::from_le_bytes([b[0], b[1]])) / 65535.0,
                    _ => (f32::from(i16::from_le_bytes([b[0], b[1]])) / 32767.0).max(-1.0),
                });
            }
        }
        Ok(out)
    }
}

/// Reads the first `KHR_gaussian_splatting` primitive of a `.glb` back into INRIA parameters
/// (log scale, opacity logit, wxyz rotation), undoing our export frame rotation.
pub fn read_glb(path: &Path) -> Result<Splats> {
    let data = read_file(path)?;
    let (json, bin) = split_chunks(path, &data)?;
    let doc = Doc {
        path,
        json: &json,
        bin: &bin,
    };
    let prim = json["meshes"]
        .as_array()
        .into_iter()
        .flatten()
        .flat_map(|m| m["primitives"].as_array().into_iter().flatten())
        .find(|p| p["extensions"].get(EXTENSION).is_some())
        .ok_or_else(|| {
            FormatError::invalid(path, "meshes", format!("no primitive uses {EXTENSION}"))
        })?;
    let attrs = &prim["attributes"];
    let get = |name: &str, width: usize| -> Result<Vec<f32>> {
        let key = if name == "POSITION" {
            name.to_owned()
        } else {
            format!("{EXTENSION}:{name}")
        };
        let idx = attrs
            .get(&key)
            .ok_or_else(|| FormatError::invalid(path, format!("attribute {key}"), "missing"))?;
        doc.accessor(idx, width, &key)
    };
    let means = get("POSITION", 3)?;
    let n = means.len() / 3;
    let degree = (1..=3)
        .take_while(|l| {
            attrs
                .get(format!("{EXTENSION}:SH_DEGREE_{l}_COEF_0"))
                .is_some()
        })
        .count() as u32;
    let mut s = Splats::with_capacity(n, degree);
    s.means = means;
    let rot = get("ROTATION", 4)?;
    s.rotations = rot
        .chunks_exact(4)
        .flat_map(|q| [q[3], q[0], q[1], q[2]])
        .collect();
    // Zero scale or α of exactly 0/1 have no finite log/logit: clamp to the nearest finite value.
    s.log_scales = get("SCALE", 3)?
        .iter()
        .map(|v| v.max(f32::MIN_POSITIVE).ln())
        .collect();
    s.opacities = get("OPACITY", 1)?
        .iter()
        .map(|a| logit(a.clamp(1e-7, 1.0 - 1e-7)))
        .collect();
    s.sh_dc = get("SH_DEGREE_0_COEF_0", 3)?;
    let k = s.rest_per_channel();
    s.sh_rest = vec![0.0; 3 * k * n];
    for l in 1..=degree as usize {
        for m in 0..2 * l + 1 {
            let coef = get(&format!("SH_DEGREE_{l}_COEF_{m}"), 3)?;
            let j = l * l - 1 + m;
            for i in 0..n.min(coef.len() / 3) {
                for c in 0..3 {
                    s.sh_rest[3 * k * i + c * k + j] = coef[3 * i + c];
                }
            }
        }
    }
    s.check().map_err(|e| {
        FormatError::invalid(path, "accessors", format!("attribute counts disagree: {e}"))
    })?;
    rotate_z180(&mut s, true);
    Ok(s)
}
