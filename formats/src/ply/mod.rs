//! PLY files: 3DGS splats in the INRIA layout and plain xyz+rgb point clouds.
//!
//! Reading goes through serde-ply (ascii, little- and big-endian; any scalar type); we inspect
//! the header first to refuse list properties and compressed files with a clear message, and
//! refuse a body that is shorter or longer than the header declares (binary: from the sizes,
//! before reading; ascii: anything but whitespace after the last element).
//! Writing is a small streaming writer, because the INRIA layout is fixed and speed matters.

mod points;
mod rows;
mod splats;

use std::cell::Cell;
use std::fs::File;
use std::io::{BufRead, BufReader, Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};
use std::rc::Rc;

use serde_ply::{ElementDef, PlyFormat, PlyHeader, PlyReader, PropertyType, ScalarType};

pub use points::{PointCloud, read_points, write_points};
pub use splats::{read_splats, write_splats};

use crate::error::{FormatError, Result};

pub(crate) type Reader = PlyReader<Counted<BufReader<std::io::Chain<File, &'static [u8]>>>>;

/// How far into the file a header scan for `end_header` looks when the header does not parse.
const HEADER_SCAN: usize = 1 << 20;

/// A reader that counts the bytes taken through it, so we know where the header ends and how
/// far the body got (serde-ply keeps its reader to itself).
pub(crate) struct Counted<R> {
    inner: R,
    pos: Rc<Cell<u64>>,
}

impl<R> Counted<R> {
    fn advance(&self, n: usize) {
        self.pos.set(self.pos.get() + n as u64);
    }
}

impl<R: Read> Read for Counted<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = self.inner.read(buf)?;
        self.advance(n);
        Ok(n)
    }

    fn read_exact(&mut self, buf: &mut [u8]) -> std::io::Result<()> {
        // Forwarded so BufReader's fast path serves whole rows.
        self.inner.read_exact(buf)?;
        self.advance(buf.len());
        Ok(())
    }
}

impl<R: BufRead> BufRead for Counted<R> {
    fn fill_buf(&mut self) -> std::io::Result<&[u8]> {
        self.inner.fill_buf()
    }

    fn consume(&mut self, amt: usize) {
        self.inner.consume(amt);
        self.advance(amt);
    }
}

/// A PLY file opened and positioned at its `vertex` element.
pub(crate) struct Opened {
    pub reader: Reader,
    pub vertex: ElementDef,
    path: PathBuf,
    header: PlyHeader,
    file_len: u64,
    pos: Rc<Cell<u64>>,
}

/// "vertices" for the vertex element, "`name` rows" for others: what a count counts.
fn rows_of(name: &str) -> String {
    if name == "vertex" {
        "vertices".to_owned()
    } else {
        format!("`{name}` rows")
    }
}

/// Bytes of one binary row of `element`, or `None` when it has a list property.
fn row_bytes(element: &ElementDef) -> Option<u64> {
    element
        .properties
        .iter()
        .map(|p| match p.property_type {
            PropertyType::Scalar(t) => Some(match t {
                ScalarType::I8 | ScalarType::U8 => 1,
                ScalarType::I16 | ScalarType::U16 => 2,
                ScalarType::I32 | ScalarType::U32 | ScalarType::F32 => 4,
                ScalarType::F64 => 8,
            }),
            PropertyType::List { .. } => None,
        })
        .sum()
}

/// Why the header of the PLY at `path` did not parse, told better than serde-ply's io error
/// where we can: a header without `end_header` reads on into the binary body.
fn header_error(path: &Path, file_len: u64, e: serde_ply::DeserializeError) -> FormatError {
    let mut head = Vec::new();
    let scanned = File::open(path)
        .and_then(|f| f.take(HEADER_SCAN as u64).read_to_end(&mut head))
        .is_ok();
    let is_ply = head.split(|&b| b == b'\n').next().map(<[u8]>::trim_ascii) == Some(b"ply");
    let has_end = head
        .split(|&b| b == b'\n')
        .any(|l| l.trim_ascii() == b"end_header");
    if scanned && is_ply && !has_end {
        let within = if file_len > HEADER_SCAN as u64 {
            format!("in the first {HEADER_SCAN} bytes")
        } else {
            format!("in the whole file ({file_len} bytes)")
        };
        return FormatError::invalid(
            path,
            "header",
            format!(
                "no `end_header` line {within}: the header never ends (truncated or not a PLY file)"
            ),
        );
    }
    if scanned && is_ply && head.ends_with(b"end_header") {
        return FormatError::invalid(
            path,
            "header",
            "`end_header` has no newline after it and ends the file: the file is truncated",
        );
    }
    FormatError::invalid(path, "header", format!("not a valid PLY header: {e}"))
}

/// A body read that failed: running out of file is said as such, with the counts involved.
fn read_error(
    path: &Path,
    element: &ElementDef,
    file_len: u64,
    e: serde_ply::DeserializeError,
) -> FormatError {
    if e.0.kind() == std::io::ErrorKind::UnexpectedEof {
        return FormatError::invalid(
            path,
            format!("element {}", element.name),
            format!(
                "the file ({file_len} bytes) ends before the {} declared {} are read: it is truncated, or the header's `element {}` count is too large",
                element.count,
                rows_of(&element.name),
                element.name
            ),
        );
    }
    FormatError::invalid(
        path,
        format!("{} data", element.name),
        format!("file truncated or malformed: {e}"),
    )
}

/// Whether the header says `format ascii`, as serde-ply itself reads it (a second parser here
/// would disagree on some header, and the newline appended to an ascii body would then go to
/// a binary one). A header that does not parse, even with a newline after it, is the real
/// parse's to report.
fn is_ascii(path: &Path) -> bool {
    File::open(path)
        .ok()
        .and_then(|f| {
            let head = BufReader::new(f.take(HEADER_SCAN as u64).chain(&b"\n"[..]));
            PlyReader::from_reader(head).ok()
        })
        .is_some_and(|r| r.header().format == PlyFormat::Ascii)
}

/// Opens a PLY file, parses its header and positions the reader at the `vertex` element.
/// Returns the reader and the vertex element definition.
pub(crate) fn open_at_vertex(path: &Path) -> Result<Opened> {
    let file = File::open(path).map_err(|e| FormatError::io(path, e))?;
    let file_len = file.metadata().map_err(|e| FormatError::io(path, e))?.len();
    let pos = Rc::new(Cell::new(0));
    // serde-ply reads each ascii value up to the whitespace after it, so a file whose last value
    // ends it would read as truncated: give such a file the newline it lacks. A binary body
    // gets nothing, or a truncated one could read the newline as its last byte.
    let tail: &'static [u8] = if is_ascii(path) { b"\n" } else { b"" };
    let mut reader = PlyReader::from_reader(Counted {
        inner: BufReader::with_capacity(1 << 20, file.chain(tail)),
        pos: Rc::clone(&pos),
    })
    .map_err(|e| header_error(path, file_len, e))?;
    let header_len = pos.get();
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
    // A binary body without list properties has an exact size: say here, before reading, which
    // element runs past the end of the file or that bytes follow the last one.
    let sizes: Option<Vec<u64>> = match header.format {
        PlyFormat::Ascii => None,
        _ => header.elem_defs.iter().map(row_bytes).collect(),
    };
    if let Some(sizes) = sizes {
        let mut offset = u128::from(header_len);
        for (element, &row) in header.elem_defs.iter().zip(&sizes) {
            let need = element.count as u128 * u128::from(row);
            // The ascii newline appended above can put the header's end past the file's.
            let left = u128::from(file_len).saturating_sub(offset);
            if need > left {
                return Err(FormatError::invalid(
                    path,
                    format!("element {}", element.name),
                    format!(
                        "the {} declared {} of {row} bytes need {need} bytes from byte {offset}, but only {left} remain (room for {} whole): the file is truncated, or the header's count is wrong",
                        element.count,
                        rows_of(&element.name),
                        left / u128::from(row.max(1)),
                    ),
                ));
            }
            offset += need;
        }
        let extra = u128::from(file_len).saturating_sub(offset);
        if let (Some(last), Some(&row)) = (header.elem_defs.last(), sizes.last())
            && extra >= u128::from(row.max(1))
        {
            return Err(trailing_error(path, last, extra, row));
        }
    }
    // A binary row has at least one byte per property and an ascii value at least two, so a
    // count larger than that is a truncated or lying header; checking first bounds allocation.
    // Every element counts, as all are read or skipped, and a property-less row is charged one
    // byte: otherwise `element junk 4000000000` with no properties is a loop of four billion
    // empty rows.
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
    }
    while reader.current_element().is_some_and(|e| e.name != "vertex") {
        let name = reader
            .current_element()
            .map(|e| e.name.clone())
            .unwrap_or_default();
        let element = header.get_element(&name).cloned().unwrap_or(ElementDef {
            name,
            count: 0,
            properties: Vec::new(),
        });
        reader
            .next_element::<rows::SkipRows>()
            .map_err(|e| read_error(path, &element, file_len, e))?;
    }
    Ok(Opened {
        reader,
        vertex,
        path: path.to_path_buf(),
        header,
        file_len,
        pos,
    })
}

/// Bytes after the last declared element: the header's count is probably wrong.
fn trailing_error(path: &Path, last: &ElementDef, extra: u128, row: u64) -> FormatError {
    let whole = if row > 0 && extra.is_multiple_of(u128::from(row)) {
        format!(
            " (exactly {} more {} of {row} bytes)",
            extra / u128::from(row),
            rows_of(&last.name)
        )
    } else {
        String::new()
    };
    FormatError::invalid(
        path,
        format!("element {}", last.name),
        format!(
            "{extra} bytes after the {} declared {}{whole}: the header's `element {}` count is probably wrong",
            last.count,
            rows_of(&last.name),
            last.name
        ),
    )
}

impl Opened {
    /// The error for a failed read of the vertex element.
    pub(crate) fn body_error(&self, e: serde_ply::DeserializeError) -> FormatError {
        read_error(&self.path, &self.vertex, self.file_len, e)
    }

    /// After the vertex element: skips the elements that follow and refuses data after the
    /// last one (binary), or anything but whitespace after it (ascii).
    pub(crate) fn finish(mut self) -> Result<()> {
        let path = self.path.as_path();
        while let Some(element) = self.reader.current_element().cloned() {
            self.reader
                .next_element::<rows::SkipRows>()
                .map_err(|e| read_error(path, &element, self.file_len, e))?;
        }
        let end = self.pos.get();
        let Some(last) = self.header.elem_defs.last() else {
            return Ok(());
        };
        let extra = self.file_len.saturating_sub(end);
        if extra == 0 {
            return Ok(());
        }
        // Fewer bytes than a row (padding, a final newline; other readers ignore them) is no
        // sign of a wrong count.
        let row = row_bytes(last);
        if self.header.format != PlyFormat::Ascii && row.is_some_and(|r| extra < r.max(1)) {
            return Ok(());
        }
        if self.header.format != PlyFormat::Ascii && row.is_some() {
            return Err(trailing_error(
                path,
                last,
                u128::from(extra),
                row.unwrap_or(0),
            ));
        }
        // Ascii, or rows of lists: trailing blank lines and spaces are common and harmless;
        // anything else is data the header does not declare.
        let mut rest = File::open(path).map_err(|e| FormatError::io(path, e))?;
        rest.seek(SeekFrom::Start(end))
            .map_err(|e| FormatError::io(path, e))?;
        let mut buf = vec![0u8; 1 << 16];
        let mut at = end;
        loop {
            let n = rest.read(&mut buf).map_err(|e| FormatError::io(path, e))?;
            if n == 0 {
                return Ok(());
            }
            if let Some(k) = buf[..n].iter().position(|b| !b.is_ascii_whitespace()) {
                return Err(FormatError::invalid(
                    path,
                    format!("element {}", last.name),
                    format!(
                        "data after the {} declared {} (from byte {}, {} bytes to the end): the header's `element {}` count is probably wrong",
                        last.count,
                        rows_of(&last.name),
                        at + k as u64,
                        self.file_len.saturating_sub(at + k as u64),
                        last.name
                    ),
                ));
            }
            at += n as u64;
        }
    }
}
