//! Range checks shared by the `.bin` and `.txt` readers. A NaN coordinate or a zero-sized
//! camera read silently would surface much later as a blank render or a panic far from the file,
//! so each record is checked as it is read. `err(field, message)` names the file and the record.

use super::{Camera, Image, Point3D};
use crate::error::{FormatError, Result};

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
