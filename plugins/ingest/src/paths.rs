//! Image paths written in dataset files stay inside the dataset folder unless the user says
//! otherwise: a downloaded transforms.json or COLMAP model must not make cocog read, and copy
//! into a scene, files such as `../../etc/x`.

use std::path::{Component, Path, PathBuf};

use cocog_pipeline::StageError;

/// `p` made absolute against the working directory with `.` and `..` resolved on the text
/// alone: the file need not exist to decide, and a symlink inside the dataset is the user's own.
fn lexical(p: &Path) -> PathBuf {
    let p = std::path::absolute(p).unwrap_or_else(|_| p.to_path_buf());
    let mut out = PathBuf::new();
    for c in p.components() {
        match c {
            Component::CurDir => {}
            Component::ParentDir => {
                out.pop();
            }
            other => out.push(other),
        }
    }
    out
}

/// Refuses `path` (a `what`, declared at `source`) unless it lies inside `dataset`.
pub(crate) fn check_inside(
    dataset: &Path,
    path: &Path,
    what: &str,
    source: &str,
) -> Result<(), StageError> {
    let (root, resolved) = (lexical(dataset), lexical(path));
    if resolved.starts_with(&root) {
        return Ok(());
    }
    Err(StageError::Input(format!(
        "{source}: the {what} path leads to {}, outside the dataset folder {}; pass --allow-outside if this is intended",
        resolved.display(),
        root.display()
    )))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dot_dot_is_resolved_without_the_file_system() {
        let d = Path::new("/data/scene");
        let ok = |p: &str| check_inside(d, &d.join(p), "image", "t").is_ok();
        assert!(ok("images/a.png"));
        assert!(ok("images/../images/./a.png"));
        assert!(!ok("../scene2/a.png"));
        assert!(!ok("images/../../x.png"));
        assert!(!ok("/etc/x"));
        assert!(!ok("../../../../../../x"));
        assert!(check_inside(Path::new("/"), Path::new("/../x"), "image", "t").is_ok());
    }
}
