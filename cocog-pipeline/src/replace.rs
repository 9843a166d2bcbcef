//! What `--force` may replace: only an output cocog wrote. A user who points `-o` at a folder
//! of their own files, the current directory or a parent of the input loses nothing.

use std::path::{Path, PathBuf};

use crate::scene::{MANIFEST, Scene};
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
    if let Some(used) = input_files(input)
        .into_iter()
        .find(|f| canonical(f).starts_with(&here))
    {
        return Some(format!(
            "it is or holds {}, which the input {} uses",
            used.display(),
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
            "it is not a file of a format cocog writes (PLY, GLB, SPZ or JSON); remove it \
             yourself or choose another output"
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
        || (head.starts_with(&[0x1f, 0x8b]) && is_spz(file))
}

/// SPZ is one gzip stream, so the magic that says cocog wrote it is inside the compression;
/// a dynamic Huffman table can precede it by more than `head` holds, so this reads the file.
fn is_spz(file: &Path) -> bool {
    use std::io::Read;
    const MAGIC: [u8; 4] = 0x5053_474e_u32.to_le_bytes();
    let mut magic = [0u8; 4];
    std::fs::File::open(file)
        .and_then(|f| flate2::read::GzDecoder::new(f).read_exact(&mut magic))
        .is_ok_and(|()| magic == MAGIC)
}

/// The files a scene input reads: its manifest and every path the manifest names. A single
/// file or a dataset folder names none, so only the checks on the input path itself apply.
fn input_files(input: &Path) -> Vec<PathBuf> {
    let manifest = input.join(MANIFEST);
    if !manifest.is_file() {
        return Vec::new();
    }
    let mut files = vec![manifest];
    // A manifest that does not load fails its stage before anything is replaced.
    if let Ok(s) = Scene::load(input) {
        files.extend(s.paths().map(|p| Scene::resolve(input, p)));
    }
    files
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

    /// A scene in `dir` whose one view's photo is `image`, as ingest stores it.
    fn scene_with_photo(dir: &Path, image: &Path) {
        let mut scene = Scene::default();
        scene.cameras.push(crate::scene::Camera {
            id: 0,
            width: 4,
            height: 4,
            fx: 4.0,
            fy: 4.0,
            cx: 2.0,
            cy: 2.0,
        });
        let mut pose = [[0.0; 4]; 4];
        (0..4).for_each(|i| pose[i][i] = 1.0);
        scene.views.push(crate::scene::View {
            name: "000.png".to_owned(),
            image: image.display().to_string(),
            camera: 0,
            world_from_camera: pose,
            split: crate::scene::Split::Train,
            lens: None,
            depth: None,
        });
        scene.gaussians = Some("gaussians.ply".to_owned());
        std::fs::create_dir_all(dir).unwrap();
        scene.save(dir).unwrap();
    }

    #[test]
    fn files_the_input_uses_are_not_replaced() {
        let tmp = tempfile::tempdir().unwrap();
        let t = tmp.path();
        // Scene `a` (marked, so replaceable on its own) holds the photo scene `b` uses.
        let a = t.join("a");
        std::fs::create_dir_all(a.join("images")).unwrap();
        std::fs::write(a.join(MARKER), b"").unwrap();
        let photo = a.join("images").join("000.png");
        std::fs::write(&photo, b"png").unwrap();
        let b = t.join("b");
        scene_with_photo(&b, &photo);
        std::fs::write(b.join("gaussians.ply"), b"ply\n").unwrap();
        let why = refusal(&a, &b, OutputKind::Dir).unwrap();
        assert!(why.contains("000.png"), "{why}");
        // The input's own manifest and a model file it names (relative to it).
        let why = refusal(&b.join(MANIFEST), &b, OutputKind::File).unwrap();
        assert!(why.contains(MANIFEST), "{why}");
        let why = refusal(&b.join("gaussians.ply"), &b, OutputKind::File).unwrap();
        assert!(why.contains("gaussians.ply"), "{why}");
        // What the scene does not name, e.g. eval's default metrics.json, stays replaceable.
        let metrics = b.join("metrics.json");
        std::fs::write(&metrics, b"{\"psnr\": 1}").unwrap();
        assert_eq!(refusal(&metrics, &b, OutputKind::File), None);
        // A single-file input names nothing: only the input itself is guarded.
        let why = refusal(&a, &photo, OutputKind::Dir).unwrap();
        assert!(why.contains("input"), "{why}");
        assert_eq!(refusal(&a, &metrics, OutputKind::Dir), None);
    }

    #[test]
    fn spz_cocog_wrote_is_replaceable() {
        let tmp = tempfile::tempdir().unwrap();
        let input = tmp.path().join("in");
        // Enough varied splats that the gzip stream opens with a dynamic Huffman table.
        let n = 500;
        let wave = |len: usize| {
            (0..len)
                .map(|i| (i as f32 * 0.37).sin())
                .collect::<Vec<_>>()
        };
        let splats = cocog_formats::Splats {
            means: wave(3 * n),
            log_scales: wave(3 * n).iter().map(|v| v - 4.0).collect(),
            rotations: wave(4 * n),
            opacities: wave(n),
            sh_dc: wave(3 * n),
            sh_rest: wave(3 * 15 * n),
            sh_degree: 3,
        };
        let spz = tmp.path().join("scene.spz");
        cocog_formats::spz::write_spz(&spz, &splats).unwrap();
        assert_eq!(refusal(&spz, &input, OutputKind::File), None);
        // A gzip stream of anything else is not cocog's.
        let other = tmp.path().join("backup.gz");
        let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
        std::io::Write::write_all(&mut gz, b"my thesis, compressed").unwrap();
        std::fs::write(&other, gz.finish().unwrap()).unwrap();
        let why = refusal(&other, &input, OutputKind::File).unwrap();
        assert!(why.contains("SPZ"), "{why}");
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
