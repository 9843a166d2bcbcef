//! Matching prediction images to ground-truth images by file stem.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use crate::MetricsError;

/// File extensions scored (compared case-insensitively).
pub const IMAGE_EXTENSIONS: [&str; 3] = ["png", "jpg", "jpeg"];

/// One prediction and the ground truth it is scored against.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ImagePair {
    /// The prediction's file stem, e.g. `000` (or `test_r_0` for the ground truth `r_0`).
    pub name: String,
    pub pred: PathBuf,
    pub gt: PathBuf,
}

/// Every PNG/JPEG in `dir` by stem. Two files with one stem (`000.png` and `000.jpg`) are refused:
/// which one is meant cannot be guessed.
fn images_by_stem(dir: &Path) -> Result<BTreeMap<String, PathBuf>, MetricsError> {
    let entries = std::fs::read_dir(dir).map_err(|source| MetricsError::Io {
        path: dir.to_path_buf(),
        source,
    })?;
    let mut found = BTreeMap::new();
    for entry in entries {
        let path = entry
            .map_err(|source| MetricsError::Io {
                path: dir.to_path_buf(),
                source,
            })?
            .path();
        let is_image = path.extension().and_then(|e| e.to_str()).is_some_and(|e| {
            IMAGE_EXTENSIONS
                .iter()
                .any(|known| known.eq_ignore_ascii_case(e))
        });
        if !is_image || !path.is_file() {
            continue;
        }
        let Some(stem) = path.file_stem().and_then(|s| s.to_str()) else {
            return Err(MetricsError::Pairing {
                path,
                reason: "file name is not valid UTF-8".into(),
            });
        };
        if let Some(previous) = found.insert(stem.to_string(), path.clone()) {
            return Err(MetricsError::Pairing {
                path: dir.to_path_buf(),
                reason: format!(
                    "two images share the stem {stem:?} ({} and {}); keep one",
                    previous.display(),
                    path.display()
                ),
            });
        }
    }
    Ok(found)
}

/// Pairs every image of `pred_dir` with the image of the same stem in `gt_dir`, sorted by name.
///
/// The predictions define the set: a ground-truth folder may hold more views (e.g. a dataset's
/// `images/` with its train views), but every prediction must have a ground truth.
pub fn pair_dirs(pred_dir: &Path, gt_dir: &Path) -> Result<Vec<ImagePair>, MetricsError> {
    let preds = images_by_stem(pred_dir)?;
    if preds.is_empty() {
        return Err(MetricsError::Pairing {
            path: pred_dir.to_path_buf(),
            reason: "no .png/.jpg/.jpeg images to score".into(),
        });
    }
    let gts = images_by_stem(gt_dir)?;
    // `cocog render` names a view whose stem another view shares by its folders joined with
    // `_` (NeRF-synthetic's test/r_0.png renders as test_r_0.png): such a prediction matches
    // `r_0` in a ground-truth folder named `test`, unless a prediction `r_0` exists too.
    // Deeper views join every folder (`images/test/r_0.png` as images_test_r_0), so the
    // folder's name may follow others. `--gt .` names its folder only once resolved.
    let folder = gt_dir
        .canonicalize()
        .ok()
        .and_then(|d| Some(format!("{}_", d.file_name()?.to_str()?)));
    let by_folder = |pred: &str| -> Option<String> {
        let folder = folder.as_deref()?;
        let at = pred
            .match_indices(folder)
            .map(|(i, _)| i)
            .find(|&i| i == 0 || pred[..i].ends_with('_'))?;
        let rest = &pred[at + folder.len()..];
        gts.contains_key(rest).then(|| rest.to_owned())
    };
    let gt_stem = |pred: &str| -> Option<String> {
        if gts.contains_key(pred) {
            return Some(pred.to_owned());
        }
        by_folder(pred).filter(|rest| !preds.contains_key(rest))
    };
    // Both `r_0` and `test_r_0` among the predictions: one ground truth for two of them.
    if let Some((pred, rest)) = preds
        .keys()
        .filter(|k| !gts.contains_key(*k))
        .find_map(|k| Some((k, by_folder(k).filter(|r| preds.contains_key(r))?)))
    {
        return Err(MetricsError::Pairing {
            path: pred_dir.to_path_buf(),
            reason: format!(
                "{pred} and {rest} would both be scored against {rest} of {}: keep one",
                gt_dir.display()
            ),
        });
    }
    let missing: Vec<&str> = preds
        .keys()
        .filter(|k| gt_stem(k).is_none())
        .map(String::as_str)
        .collect();
    if !missing.is_empty() {
        let shown = missing
            .iter()
            .take(5)
            .copied()
            .collect::<Vec<_>>()
            .join(", ");
        let more = if missing.len() > 5 {
            format!(" and {} more", missing.len() - 5)
        } else {
            String::new()
        };
        return Err(MetricsError::Pairing {
            path: gt_dir.to_path_buf(),
            reason: format!(
                "no ground truth for {} prediction(s) of {}: {shown}{more} \
                 (images are matched by file stem)",
                missing.len(),
                pred_dir.display()
            ),
        });
    }
    let pairs = preds
        .iter()
        .filter_map(|(name, pred)| {
            let gt = gts[&gt_stem(name)?].clone();
            Some(ImagePair {
                name: name.clone(),
                pred: pred.clone(),
                gt,
            })
        })
        .collect();
    Ok(pairs)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn touch(dir: &Path, name: &str) {
        std::fs::write(dir.join(name), b"").unwrap();
    }

    #[test]
    fn pairs_by_stem_across_extensions_and_ignores_extra_gt() {
        let (p, g) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
        for n in ["008.png", "000.PNG", "notes.txt"] {
            touch(p.path(), n);
        }
        for n in ["000.jpg", "001.png", "008.png"] {
            touch(g.path(), n);
        }
        let pairs = pair_dirs(p.path(), g.path()).unwrap();
        let names: Vec<_> = pairs.iter().map(|p| p.name.as_str()).collect();
        assert_eq!(names, ["000", "008"]);
        assert_eq!(pairs[0].gt, g.path().join("000.jpg"));
    }

    #[test]
    fn a_render_name_carrying_the_folder_matches_the_ground_truth_in_that_folder() {
        let (p, root) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
        let g = root.path().join("test");
        std::fs::create_dir(&g).unwrap();
        for n in ["test_r_0.png", "test_r_1.png", "r_2.png"] {
            touch(p.path(), n);
        }
        for n in ["r_0.png", "r_1.png", "r_2.png", "test_r_2.png"] {
            touch(&g, n);
        }
        let pairs = pair_dirs(p.path(), &g).unwrap();
        let got: Vec<_> = pairs
            .iter()
            .map(|p| (p.name.as_str(), p.gt.file_name().unwrap().to_str().unwrap()))
            .collect();
        // An exact stem wins over the folder rule.
        assert_eq!(
            got,
            [
                ("r_2", "r_2.png"),
                ("test_r_0", "r_0.png"),
                ("test_r_1", "r_1.png")
            ]
        );
        // Only the folder the ground truth is in: `train_r_0` is not `test/r_0`.
        touch(p.path(), "train_r_0.png");
        let e = pair_dirs(p.path(), &g).unwrap_err().to_string();
        assert!(e.contains("no ground truth for 1 prediction(s)"), "{e}");
        // Where `r_0` is itself a prediction, one ground truth would be scored twice.
        std::fs::remove_file(p.path().join("train_r_0.png")).unwrap();
        touch(p.path(), "r_0.png");
        let e = pair_dirs(p.path(), &g).unwrap_err().to_string();
        assert!(
            e.contains("test_r_0 and r_0 would both be scored against r_0"),
            "{e}"
        );
        // Folders before the ground truth's are joined too; `--gt test/sub/..` is resolved.
        std::fs::remove_file(p.path().join("r_0.png")).unwrap();
        std::fs::remove_file(p.path().join("test_r_0.png")).unwrap();
        touch(p.path(), "images_test_r_0.png");
        touch(p.path(), "xtest_r_1.png");
        let e = pair_dirs(p.path(), &g).unwrap_err().to_string();
        assert!(
            e.contains("1 prediction(s)") && e.contains("xtest_r_1"),
            "{e}"
        );
        std::fs::remove_file(p.path().join("xtest_r_1.png")).unwrap();
        std::fs::create_dir(g.join("sub")).unwrap();
        let pairs = pair_dirs(p.path(), &g.join("sub/..")).unwrap();
        let names: Vec<_> = pairs.into_iter().map(|p| p.name).collect();
        assert_eq!(names, ["images_test_r_0", "r_2", "test_r_1"]);
    }

    #[test]
    fn missing_ground_truth_names_the_images() {
        let (p, g) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
        touch(p.path(), "000.png");
        touch(p.path(), "016.png");
        touch(g.path(), "000.png");
        let err = pair_dirs(p.path(), g.path()).unwrap_err().to_string();
        assert!(err.contains("016") && err.contains("1 prediction"), "{err}");
    }

    #[test]
    fn duplicate_stems_and_empty_folders_are_refused() {
        let (p, g) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
        let err = pair_dirs(p.path(), g.path()).unwrap_err().to_string();
        assert!(err.contains("no .png"), "{err}");
        touch(p.path(), "000.png");
        touch(p.path(), "000.jpg");
        let err = pair_dirs(p.path(), g.path()).unwrap_err().to_string();
        assert!(err.contains("share the stem"), "{err}");
    }

    #[test]
    fn a_missing_folder_is_an_io_error_naming_it() {
        let g = tempfile::tempdir().unwrap();
        let err = pair_dirs(&g.path().join("nope"), g.path()).unwrap_err();
        assert!(matches!(err, MetricsError::Io { .. }));
        assert!(err.to_string().contains("nope"));
    }
}
