//! What `--force` may replace: only an output cocog wrote. A user who points `-o` at a folder
//! of their own files, the current directory or a parent of the input loses nothing.

use std::path::{Path, PathBuf};

use crate::scene::MANIFEST;
use crate::stage::OutputKind;

/// Written into every folder output the runner commits, so a later `--force` knows it.
pub const MARKER: &str = ".cocog-output";

/// Why `output` must not be replaced, or `None` when cocog made it and may replace it.
pub fn refusal(output: &Path, input: &Path, kind: OutputKind) -> Option<String> {
    let meta = std::fs::symlink_metadata(output).ok()?;
    if meta.file_type().is_symlink() {
        return Some("it is a symbolic link, which cocog never writes".to_owned());
    }
    let here = canonical(output);
    if let Ok(cwd) = std::env::current_dir()
        && canonical(&cwd).starts_with(&here)
    {
        return Some("it is the current directory or contains it".to_owned());
    }
    if canonical(input).starts_with(&here) {
        return Some(format!(
            "it is the input {} or contains it",
            input.display()
        ));
    }
    match kind {
        OutputKind::File if meta.is_dir() => Some(
            "it is a folder, and this stage writes one file: name the file, e.g. \
             -o exports/scene.ply"
                .to_owned(),
        ),
        OutputKind::File if written_by_cocog(output) => None,
        OutputKind::File => Some(
            "it is not a file of a format cocog writes (PLY, GLB or JSON); remove it yourself \
             or choose another output"
                .to_owned(),
        ),
        OutputKind::Dir if !meta.is_dir() => {
            Some("it is a file, and this stage writes a folder".to_owned())
        }
        OutputKind::Dir if output.join(MARKER).is_file() || is_cocog_scene(output) => None,
        OutputKind::Dir => Some(format!(
            "it is a folder cocog did not write (it has no {MARKER} or cocog scene.json); \
             remove it yourself or choose another output"
        )),
    }
}

/// File outputs carry no marker, so their first bytes must be a format a file stage writes.
fn written_by_cocog(file: &Path) -> bool {
    use std::io::Read;
    let mut head = [0u8; 64];
    let n = std::fs::File::open(file)
        .and_then(|mut f| f.read(&mut head))
        .unwrap_or(0);
    let head = &head[..n];
    head.starts_with(b"ply\n")
        || head.starts_with(b"glTF")
        || head.trim_ascii_start().starts_with(b"{")
}

/// A scene written before outputs carried the marker.
fn is_cocog_scene(dir: &Path) -> bool {
    std::fs::read_to_string(dir.join(MANIFEST))
        .ok()
        .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
        .is_some_and(|v| v["format"] == crate::scene::FORMAT)
}

fn canonical(p: &Path) -> PathBuf {
    p.canonicalize().unwrap_or_else(|_| p.to_path_buf())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_what_cocog_wrote_is_replaceable() {
        let tmp = tempfile::tempdir().unwrap();
        let t = tmp.path();
        let input = t.join("in");
        std::fs::create_dir(&input).unwrap();
        // A folder of the user's files.
        let user = t.join("photos");
        std::fs::create_dir(&user).unwrap();
        std::fs::write(user.join("a.jpg"), b"x").unwrap();
        let why = refusal(&user, &input, OutputKind::Dir).unwrap();
        assert!(why.contains("did not write"), "{why}");
        assert!(
            refusal(&user, &input, OutputKind::File)
                .unwrap()
                .contains("folder")
        );
        // A marked output folder, and a legacy scene.
        let made = t.join("made");
        std::fs::create_dir(&made).unwrap();
        std::fs::write(made.join(MARKER), b"").unwrap();
        assert_eq!(refusal(&made, &input, OutputKind::Dir), None);
        let legacy = t.join("legacy");
        std::fs::create_dir(&legacy).unwrap();
        std::fs::write(legacy.join(MANIFEST), r#"{"format": "cocog.scene"}"#).unwrap();
        assert_eq!(refusal(&legacy, &input, OutputKind::Dir), None);
        std::fs::write(legacy.join(MANIFEST), r#"{"format": "other"}"#).unwrap();
        assert!(refusal(&legacy, &input, OutputKind::Dir).is_some());
        // Files: replaceable by a file stage, not by a folder stage.
        let ply = t.join("scene.ply");
        std::fs::write(&ply, b"ply\n").unwrap();
        assert_eq!(refusal(&ply, &input, OutputKind::File), None);
        let glb = t.join("scene.glb");
        std::fs::write(&glb, b"glTF\x02\0\0\0").unwrap();
        assert_eq!(refusal(&glb, &input, OutputKind::File), None);
        let json = t.join("metrics.json");
        std::fs::write(&json, b"\n  {\"psnr\": 1}").unwrap();
        assert_eq!(refusal(&json, &input, OutputKind::File), None);
        let notes = t.join("notes.txt");
        std::fs::write(&notes, b"my thesis").unwrap();
        let why = refusal(&notes, &input, OutputKind::File).unwrap();
        assert!(why.contains("format"), "{why}");
        assert!(
            refusal(&ply, &input, OutputKind::Dir)
                .unwrap()
                .contains("file")
        );
        // The input's parent, even when marked; a missing output is no question.
        std::fs::write(t.join(MARKER), b"").unwrap();
        let why = refusal(t, &input, OutputKind::Dir).unwrap();
        assert!(why.contains("input"), "{why}");
        assert_eq!(refusal(&t.join("absent"), &input, OutputKind::Dir), None);
    }

    #[cfg(unix)]
    #[test]
    fn links_are_refused() {
        let tmp = tempfile::tempdir().unwrap();
        let link = tmp.path().join("link");
        std::os::unix::fs::symlink(tmp.path(), &link).unwrap();
        let why = refusal(&link, &tmp.path().join("in"), OutputKind::File).unwrap();
        assert!(why.contains("symbolic link"), "{why}");
    }
}
