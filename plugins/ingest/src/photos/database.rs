//! What COLMAP's database says about each image: how many features it found and which other
//! images it verified matches with. That is COLMAP's own evidence for why an image did not
//! register, which the stage reports per image.

use std::collections::{BTreeMap, HashSet};
use std::path::Path;

use cocog_pipeline::StageError;
use rusqlite::{Connection, OpenFlags, OptionalExtension};

/// COLMAP packs an image pair into one integer: `id1 * MAX_IMAGE_ID + id2` with id1 < id2.
const MAX_IMAGE_ID: i64 = 2_147_483_647;

/// The mapper's default `Mapper.min_num_matches`: pairs with fewer inliers are ignored.
pub(crate) const MIN_MATCHES: u64 = 15;

pub(crate) struct ImageEvidence {
    pub features: u64,
    /// (other image name, inlier matches) for every geometrically verified pair.
    pub verified: Vec<(String, u64)>,
}

/// Per image name: features and verified pairs.
fn failed(db: &Path, e: rusqlite::Error) -> StageError {
    StageError::Input(format!("{}: reading COLMAP's database: {e}", db.display()))
}

fn open(db: &Path) -> Result<Connection, StageError> {
    // Read-write although nothing is written: COLMAP's database is in WAL mode, where a
    // read-only connection leaves -wal/-shm files behind that only a writer removes on close.
    Connection::open_with_flags(db, OpenFlags::SQLITE_OPEN_READ_WRITE).map_err(|e| failed(db, e))
}

pub(crate) fn read(db: &Path) -> Result<BTreeMap<String, ImageEvidence>, StageError> {
    let fail = |e| failed(db, e);
    let conn = open(db)?;
    // Every query here yields (integer, value) rows.
    fn rows<T: rusqlite::types::FromSql>(
        conn: &Connection,
        sql: &str,
    ) -> rusqlite::Result<Vec<(i64, T)>> {
        let mut stmt = conn.prepare(sql)?;
        stmt.query_map([], |r| Ok((r.get(0)?, r.get(1)?)))?
            .collect()
    }
    let names: BTreeMap<i64, String> = rows(&conn, "SELECT image_id, name FROM images")
        .map_err(fail)?
        .into_iter()
        .collect();
    let mut out: BTreeMap<String, ImageEvidence> = names
        .values()
        .map(|n| {
            let e = ImageEvidence {
                features: 0,
                verified: Vec::new(),
            };
            (n.clone(), e)
        })
        .collect();
    for (id, features) in
        rows::<i64>(&conn, "SELECT image_id, rows FROM keypoints").map_err(fail)?
    {
        if let Some(e) = names.get(&id).and_then(|n| out.get_mut(n)) {
            e.features = features.max(0) as u64;
        }
    }
    let pairs = "SELECT pair_id, rows FROM two_view_geometries WHERE rows > 0";
    for (pair, inliers) in rows::<i64>(&conn, pairs).map_err(fail)? {
        let (a, b) = (pair / MAX_IMAGE_ID, pair % MAX_IMAGE_ID);
        if let (Some(na), Some(nb)) = (names.get(&a), names.get(&b)) {
            for (me, other) in [(na, nb), (nb, na)] {
                if let Some(e) = out.get_mut(me) {
                    e.verified.push((other.clone(), inliers as u64));
                }
            }
        }
    }
    Ok(out)
}

/// Why `name` is not in the kept model, in COLMAP's terms.
pub(crate) fn reason(
    name: &str,
    evidence: &BTreeMap<String, ImageEvidence>,
    kept: &HashSet<String>,
    in_other_model: bool,
) -> String {
    let Some(e) = evidence.get(name) else {
        return "COLMAP could not read the image".to_owned();
    };
    if e.features == 0 {
        return "COLMAP found no SIFT features in it (blank, or too blurred at every scale)"
            .to_owned();
    }
    let usable: Vec<&(String, u64)> = e
        .verified
        .iter()
        .filter(|(_, n)| *n >= MIN_MATCHES)
        .collect();
    if usable.is_empty() {
        let best = e.verified.iter().map(|(_, n)| *n).max().unwrap_or(0);
        return format!(
            "{} features, but no other image shares {MIN_MATCHES} verified matches with it \
             (best: {best})",
            e.features
        );
    }
    if in_other_model {
        return format!(
            "it is in a separate, smaller model: it matches {} image(s), none of them in the \
             kept model with enough overlap to join them",
            usable.len()
        );
    }
    let with_kept = usable.iter().filter(|(o, _)| kept.contains(o)).count();
    format!(
        "{} features and verified matches with {} image(s) ({with_kept} in the model), but \
         COLMAP's mapper could not estimate its pose from them",
        e.features,
        usable.len()
    )
}

/// The focal length the first camera starts from (EXIF, else the default factor × the longer
/// side): the mapper holds it, so the summary reports it. `None` for an empty table.
pub(crate) fn focal_prior(db: &Path) -> Result<Option<f64>, StageError> {
    let params: Option<Vec<u8>> = open(db)?
        .query_row(
            "SELECT params FROM cameras ORDER BY camera_id LIMIT 1",
            [],
            |r| r.get(0),
        )
        .optional()
        .map_err(|e| failed(db, e))?;
    // Every COLMAP camera model stores its (first) focal length as the first little-endian f64.
    Ok(params.and_then(|p| {
        p.get(..8)
            .map(|b| f64::from_le_bytes(b.try_into().expect("8 bytes")))
    }))
}
