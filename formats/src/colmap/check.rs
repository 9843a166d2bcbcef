//! Range checks shared by the `.bin` and `.txt` readers. A NaN coordinate or a zero-sized
//! camera read silently would surface much later as a blank render or a panic far from the file,
//! so each record is checked as it is read. `err(field, message)` names the file and the record.

use std::collections::HashMap;
use std::collections::hash_map::Entry;
use std::hash::Hash;

use super::{Camera, Image, Point3D};
use crate::error::{FormatError, Result};

/// Focal lengths above this many times the image size (a field of view under about two
/// microradians) are unit mistakes, and overflow the renderer's f32 arithmetic long before 1e308.
pub(crate) const MAX_FOCAL_PER_PIXEL: f64 = 1e6;

/// Numbers as a person reads them: `1e308`, not three hundred digits.
pub(crate) fn show(v: f64) -> String {
    if v != 0.0 && !(1e-6..1e9).contains(&v.abs()) {
        format!("{v:e}")
    } else {
        format!("{v}")
    }
}

/// Why focal length `key = f` cannot be used for an image `size` pixels across, if it cannot.
pub(crate) fn focal(key: &str, f: f64, size: f64) -> Result<(), String> {
    if f.is_finite() && f > 0.0 && f <= MAX_FOCAL_PER_PIXEL * size {
        return Ok(());
    }
    Err(format!(
        "{key} = {} px is not a usable focal length for an image {} px across: expected above 0 and at most {} px ({} × the size)",
        show(f),
        show(size),
        show(MAX_FOCAL_PER_PIXEL * size),
        show(MAX_FOCAL_PER_PIXEL)
    ))
}

fn finite(values: &[f64], name: &str, err: &impl Fn(&str, String) -> FormatError) -> Result<()> {
    match values.iter().position(|v| !v.is_finite()) {
        Some(k) => Err(err(
            &format!("{name}[{k}]"),
            format!("expected a finite number, got {}", values[k]),
        )),
        None => Ok(()),
    }
}

pub(crate) fn camera(c: &Camera, err: impl Fn(&str, String) -> FormatError) -> Result<()> {
    for (name, v) in [("width", c.width), ("height", c.height)] {
        // Scenes store sizes as u32.
        if v == 0 || v > u64::from(u32::MAX) {
            return Err(err(
                name,
                format!("expected 1 to {} pixels, got {v}", u32::MAX),
            ));
        }
    }
    finite(&c.params, "params", &err)
}

pub(crate) fn image(img: &Image, err: impl Fn(&str, String) -> FormatError) -> Result<()> {
    finite(&img.qvec, "qvec", &err)?;
    finite(&img.tvec, "tvec", &err)?;
    if img.qvec.iter().map(|v| v * v).sum::<f64>() < 1e-12 {
        return Err(err(
            "qvec",
            "quaternion is zero, expected a rotation (QW QX QY QZ, not all zero)".to_owned(),
        ));
    }
    Ok(())
}

pub(crate) fn point(p: &Point3D, err: impl Fn(&str, String) -> FormatError) -> Result<()> {
    finite(&p.xyz, "xyz", &err)
}

/// Ids seen so far in one file, each with where it was first seen (a record index or a line).
/// COLMAP keys every record by its id, so a second record with the same id is either dropped or
/// overwrites the first depending on the reader; we refuse the file instead.
pub(crate) struct Ids<K>(HashMap<K, usize>);

impl<K: Hash + Eq> Ids<K> {
    pub(crate) fn with_capacity(n: usize) -> Self {
        Self(HashMap::with_capacity(n))
    }

    /// Records `id` as seen at `at`, or returns where it was seen first.
    pub(crate) fn repeat(&mut self, id: K, at: usize) -> Option<usize> {
        match self.0.entry(id) {
            Entry::Occupied(first) => Some(*first.get()),
            Entry::Vacant(slot) => {
                slot.insert(at);
                None
            }
        }
    }
}
