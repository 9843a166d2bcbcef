//! PLY files: 3DGS splats in the INRIA layout and plain xyz+rgb point clouds.
//!
//! Reading goes through serde-ply (ascii, little- and big-endian; any scalar type); we inspect
//! the header first to refuse list properties and compressed files with a clear message.
//! Writing is a small streaming writer, because the INRIA layout is fixed and speed matters.

mod points;
mod rows;
mod splats;

use std::fs::File;
use std::io::BufReader;
use std::path::Path;

use serde_ply::{ElementDef, PlyReader, PropertyType};

pub use points::{PointCloud, read_points, write_points};
pub use splats::{read_splats, write_splats};

use crate::error::{FormatError, Result};

pub(crate) type Reader = PlyReader<BufReader<File>>;

/// Opens a PLY file, parses its header and positions the reader at the `vertex` element.
/// Returns the reader and the vertex element definition.
pub(crate) fn open_at_vertex(path: &Path) -> Result<(Reader, ElementDef)> {
    let file = File::open(path).map_err(|e| FormatError::io(path, e))?;
    let file_len = file.metadata().map_err(|e| FormatError::io(path, e))?.len();
    let mut reader =
        PlyReader::from_reader(BufReader::with_capacity(1 << 20, file)).map_err(|e| {
            FormatError::invalid(path, "header", format!("not a valid PLY header: {e}"))
        })?;
    let header = reader.header().clone();
    if header.has_element("chunk")
        && header
            .get_element("vertex")
            .is_some_and(|v| v.has_property("packed_position"))
    {
        return Err(FormatError::unsupported(
            path,
            "SuperSplat compressed PLY (chunk + packed_position); decompress it with splat-transform first",
        ));
    }
    let Some(vertex) = header.get_element("vertex").cloned() else {
        return Err(FormatError::invalid(
            path,
            "element vertex",
            "the file has no vertex element",
        ));
    };
    if let Some(list) = vertex
        .properties
        .iter()
        .find(|p| matches!(p.property_type, PropertyType::List { .. }))
    {
        return Err(FormatError::unsupported(
            path,
            format!(
                "vertex property {:?} is a list property; splat and point PLYs have only scalar vertex properties",
                list.name
            ),
        ));
    }
    // A binary row has at least one byte per property and an ascii value at least two, so a
    // count larger than that is a truncated or lying header; checking first bounds allocation.
    // Elements read (or skipped) before the vertex count too, and a property-less row is
    // charged one byte: otherwise `element junk 4000000000` with no properties is a loop of
    // four billion empty rows before the first vertex.
    let mut min_bytes = 0u128;
    for element in &header.elem_defs {
        min_bytes += element.count as u128 * element.properties.len().max(1) as u128;
        if min_bytes > u128::from(file_len) {
            return Err(FormatError::invalid(
                path,
                format!("element {}", element.name),
                format!(
                    "count {} cannot fit: the file has only {file_len} bytes (truncated?)",
                    element.count
                ),
            ));
        }
        if element.name == "vertex" {
            break;
        }
    }
    while reader.current_element().is_some_and(|e| e.name != "vertex") {
        let name = reader
            .current_element()
            .map(|e| e.name.clone())
            .unwrap_or_default();
        reader.next_element::<rows::SkipRows>().map_err(|e| {
            FormatError::invalid(
                path,
                format!("element {name}"),
                format!("cannot skip element: {e}"),
            )
        })?;
    }
    Ok((reader, vertex))
}

/// Error for a malformed vertex body.
pub(crate) fn body_error(path: &Path, e: serde_ply::DeserializeError) -> FormatError {
    FormatError::invalid(
        path,
        "vertex data",
        format!("file truncated or malformed: {e}"),
    )
}
