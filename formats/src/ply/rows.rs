//! Streaming serde seeds that turn PLY rows into f32 values by field name, without a per-row
//! allocation, so large files are read straight into structure-of-arrays storage.

use std::fmt;

use serde::Deserialize;
use serde::de::{DeserializeSeed, Deserializer, IgnoredAny, MapAccess, SeqAccess, Visitor};

/// The most fields a row can carry (the INRIA layout without normals has 59).
pub(crate) const MAX_FIELDS: usize = 64;

/// One row: `vals[i]` holds field `i` of the list it was read with; bit `i` of `seen` says it was present.
pub(crate) struct Row {
    pub vals: [f32; MAX_FIELDS],
    pub seen: u64,
}

struct RowSeed {
    fields: &'static [&'static str],
}

impl<'de> DeserializeSeed<'de> for RowSeed {
    type Value = Row;
    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<Row, D::Error> {
        // As a struct, serde-ply serves binary rows by precomputed offsets (its fast path).
        d.deserialize_struct("Row", self.fields, self)
    }
}

/// Maps a property name to its index in the field list, or `None` for a property we skip.
struct KeySeed<'a>(&'a [&'static str]);

impl<'de> DeserializeSeed<'de> for KeySeed<'_> {
    type Value = Option<usize>;
    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<Self::Value, D::Error> {
        d.deserialize_identifier(self)
    }
}

impl<'de> Visitor<'de> for KeySeed<'_> {
    type Value = Option<usize>;
    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("a property name")
    }
    fn visit_str<E>(self, v: &str) -> Result<Self::Value, E> {
        Ok(self.0.iter().position(|f| *f == v))
    }
    fn visit_bytes<E>(self, v: &[u8]) -> Result<Self::Value, E> {
        Ok(self.0.iter().position(|f| f.as_bytes() == v))
    }
}

impl<'de> Visitor<'de> for RowSeed {
    type Value = Row;
    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("a PLY row")
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Row, A::Error> {
        let mut row = Row {
            vals: [0.0; MAX_FIELDS],
            seen: 0,
        };
        // serde-ply yields `None` for a field the file lacks and then carries on with the next.
        for i in 0..self.fields.len() {
            if let Some(v) = seq.next_element::<f32>()? {
                row.vals[i] = v;
                row.seen |= 1 << i;
            }
        }
        Ok(row)
    }

    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<Row, A::Error> {
        let mut row = Row {
            vals: [0.0; MAX_FIELDS],
            seen: 0,
        };
        while let Some(key) = map.next_key_seed(KeySeed(self.fields))? {
            match key {
                Some(i) => {
                    row.vals[i] = map.next_value::<f32>()?;
                    row.seen |= 1 << i;
                }
                None => {
                    map.next_value::<IgnoredAny>()?;
                }
            }
        }
        Ok(row)
    }
}

/// Reads every row of the current element and hands it to `sink`.
pub(crate) struct Rows<F: FnMut(&Row) -> Result<(), String>> {
    pub fields: &'static [&'static str],
    pub sink: F,
}

impl<'de, F: FnMut(&Row) -> Result<(), String>> DeserializeSeed<'de> for Rows<F> {
    type Value = ();
    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<(), D::Error> {
        d.deserialize_seq(self)
    }
}

impl<'de, F: FnMut(&Row) -> Result<(), String>> Visitor<'de> for Rows<F> {
    type Value = ();
    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("a sequence of PLY rows")
    }
    fn visit_seq<A: SeqAccess<'de>>(mut self, mut seq: A) -> Result<(), A::Error> {
        while let Some(row) = seq.next_element_seed(RowSeed {
            fields: self.fields,
        })? {
            (self.sink)(&row).map_err(serde::de::Error::custom)?;
        }
        Ok(())
    }
}

/// Consumes an element we do not use (any properties, lists included).
pub(crate) struct SkipRows;

impl<'de> Deserialize<'de> for SkipRows {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = SkipRows;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("rows")
            }
            fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<SkipRows, A::Error> {
                while seq.next_element::<SkipRow>()?.is_some() {}
                Ok(SkipRows)
            }
        }
        d.deserialize_seq(V)
    }
}

struct SkipRow;

impl<'de> Deserialize<'de> for SkipRow {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = SkipRow;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("a row")
            }
            fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<SkipRow, A::Error> {
                while map.next_key::<IgnoredAny>()?.is_some() {
                    map.next_value::<IgnoredAny>()?;
                }
                Ok(SkipRow)
            }
        }
        d.deserialize_map(V)
    }
}

/// Reads the vertex element (the reader must be positioned at it) through `sink`.
pub(crate) fn read_vertex<F: FnMut(&Row) -> Result<(), String>>(
    reader: &mut super::Reader,
    fields: &'static [&'static str],
    sink: F,
) -> Result<(), serde_ply::DeserializeError> {
    // `PlyReader` is a map of element name → rows; taking the value directly streams the rows.
    let mut map = reader;
    MapAccess::next_value_seed(&mut map, Rows { fields, sink })
}
