//! `cocog render --focus-sweep`: a focus pull over one view, as PNG frames, an animated GIF,
//! or an MP4 through ffmpeg when it is installed.

use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::{Context as _, Result, bail};
use cocog_pipeline::Context;
use cocog_pipeline::runner::run_stage;
use serde_json::{Map, Value};

use crate::cli::{Global, RenderArgs};
use crate::commands::{UsageError, print_result, resolve};

/// Frames per second of the animations.
const FPS: u32 = 12;

#[derive(Clone, Copy, Debug, PartialEq)]
enum Target {
    Frames,
    Gif,
    Mp4,
}

fn target(output: &Path) -> Target {
    match output
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
        .as_deref()
    {
        Some("gif") => Target::Gif,
        Some("mp4") => Target::Mp4,
        _ => Target::Frames,
    }
}

pub fn run(
    registry: &cocog_pipeline::Registry,
    a: &RenderArgs,
    sweep: &str,
    mut options: Map<String, Value>,
    g: &Global,
    ctx: &dyn Context,
) -> Result<()> {
    options.insert("focus_sweep".into(), Value::from(sweep));
    let entry = resolve(registry, "render")?;
    let output = &a.io.output;
    let kind = target(output);
    if kind == Target::Frames {
        let summary = run_stage(entry, &a.io.scene, output, &options, g.force, ctx)?;
        return print_result(g, &summary, output);
    }
    if kind == Target::Mp4 && !ffmpeg_available() {
        return Err(UsageError(format!(
            "{}: writing MP4 needs ffmpeg on PATH (Debian/Ubuntu: apt install ffmpeg); without \
             it, write an animated GIF (-o pull.gif) or the frames (-o DIR/)",
            output.display()
        ))
        .into());
    }
    if output.exists() && !(g.force && is_animation(output)) {
        bail!(
            "{}: exists{}",
            output.display(),
            if g.force {
                " and is not a GIF or MP4 cocog would write; not replaced"
            } else {
                " (use --force to replace it)"
            }
        );
    }
    // Named as the runner's staging, so a killed run's folder goes with the next run's.
    cocog_pipeline::atomic::remove_stale_temps(output);
    let work =
        cocog_pipeline::atomic::scratch_beside(&cocog_pipeline::atomic::sibling_temp(output))
            .with_context(|| {
                format!("{}: cannot make a work folder beside it", output.display())
            })?;
    let frames_dir = work.path().join("frames");
    let mut summary = run_stage(entry, &a.io.scene, &frames_dir, &options, false, ctx)?;
    let frames = frame_files(&frames_dir)?;
    let tmp = work.path().join("out");
    match kind {
        Target::Gif => write_gif(&frames, &tmp)?,
        _ => write_mp4(&frames_dir, &tmp)?,
    }
    std::fs::rename(&tmp, output)
        .or_else(|_| std::fs::copy(&tmp, output).map(|_| ()))
        .with_context(|| format!("{}: cannot write", output.display()))?;
    if let Value::Object(m) = &mut summary {
        m.insert("output".into(), Value::from(output.display().to_string()));
        m.insert("fps".into(), Value::from(FPS));
    }
    print_result(g, &summary, output)
}

pub(crate) fn frame_files(dir: &Path) -> Result<Vec<PathBuf>> {
    let mut frames: Vec<PathBuf> = std::fs::read_dir(dir)
        .with_context(|| format!("{}", dir.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.file_name()
                .and_then(|n| n.to_str())
                .is_some_and(|n| n.starts_with("frame-") && n.ends_with(".png"))
        })
        .collect();
    frames.sort();
    if frames.is_empty() {
        bail!("{}: the render wrote no frames", dir.display());
    }
    Ok(frames)
}

pub(crate) fn write_gif(frames: &[PathBuf], out: &Path) -> Result<()> {
    use image::codecs::gif::{GifEncoder, Repeat};
    use image::{Delay, Frame};
    let file = std::fs::File::create(out).with_context(|| format!("{}", out.display()))?;
    let mut enc = GifEncoder::new_with_speed(std::io::BufWriter::new(file), 10);
    enc.set_repeat(Repeat::Infinite)?;
    let delay = Delay::from_numer_denom_ms(1000, FPS);
    for f in frames {
        let img = image::open(f)
            .with_context(|| format!("{}", f.display()))?
            .to_rgba8();
        enc.encode_frame(Frame::from_parts(img, 0, 0, delay))
            .with_context(|| format!("encoding {}", f.display()))?;
    }
    Ok(())
}

fn ffmpeg_available() -> bool {
    Command::new("ffmpeg")
        .arg("-version")
        .output()
        .is_ok_and(|o| o.status.success())
}

fn write_mp4(frames_dir: &Path, out: &Path) -> Result<()> {
    let status = Command::new("ffmpeg")
        .args(["-loglevel", "error", "-y", "-framerate"])
        .arg(FPS.to_string())
        .arg("-i")
        .arg(frames_dir.join("frame-%03d.png"))
        // yuv420p plays everywhere; it needs even sizes.
        .args([
            "-vf",
            "scale=trunc(iw/2)*2:trunc(ih/2)*2",
            "-pix_fmt",
            "yuv420p",
            "-f",
            "mp4",
        ])
        .arg(out)
        .status()
        .context("running ffmpeg")?;
    if !status.success() {
        bail!("ffmpeg failed ({status}) encoding {}", frames_dir.display());
    }
    Ok(())
}

/// A file cocog may replace: a GIF or an MP4 (ISO base media: `ftyp` at byte 4).
fn is_animation(path: &Path) -> bool {
    let mut head = [0u8; 12];
    let n = std::fs::File::open(path)
        .and_then(|mut f| std::io::Read::read(&mut f, &mut head))
        .unwrap_or(0);
    n >= 6 && (&head[..4] == b"GIF8" || (n >= 8 && &head[4..8] == b"ftyp"))
}
