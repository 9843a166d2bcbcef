//! Generation: render every view on worker threads, then write the metadata, all inside a
//! hidden sibling directory that is renamed into place only when everything succeeded.

use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::time::Instant;

use cocog_engine::reference::{Image64, render};
use cocog_formats::colmap::write_txt;
use cocog_formats::llff::{LlffView, write_poses_bounds};

use crate::files::{ViewStats, write_lens, write_png, write_transforms};
use crate::lens::{quantize, render_thin_lens};
use crate::rig::{Split, ViewSpec, view_specs};
use crate::scene::{Scene, tabletop};
use crate::sparse::{build_model, depth_bounds};
use crate::{SynthConfig, SynthError, SynthSummary, io_err};

static TEMP_COUNTER: AtomicU64 = AtomicU64::new(0);

/// Generates the dataset of `cfg` into `dir`, which must not exist yet. Either the whole
/// dataset appears at `dir` or nothing does.
pub fn write_defocus_dataset(dir: &Path, cfg: &SynthConfig) -> Result<SynthSummary, SynthError> {
    generate(dir, cfg, |_| Ok(()))
}

/// `before_commit` runs on the finished temp directory just before the rename; tests use it
/// to fail at the last moment.
pub(crate) fn generate(
    dir: &Path,
    cfg: &SynthConfig,
    before_commit: impl FnOnce(&Path) -> Result<(), SynthError>,
) -> Result<SynthSummary, SynthError> {
    cfg.validate()?;
    if dir.symlink_metadata().is_ok() {
        return Err(SynthError::Exists(dir.to_owned()));
    }
    let name = dir
        .file_name()
        .ok_or_else(|| SynthError::Config(format!("{}: not a directory name", dir.display())))?;
    let parent = dir.parent().filter(|p| !p.as_os_str().is_empty());
    let n = TEMP_COUNTER.fetch_add(1, Ordering::Relaxed);
    // A sibling, so the final rename stays on one filesystem; the name matches .gitignore.
    let tmp_name = format!(
        ".{}.cocog-tmp-{}-{n}",
        name.to_string_lossy(),
        std::process::id()
    );
    let tmp = parent.map_or_else(|| PathBuf::from(&tmp_name), |p| p.join(&tmp_name));
    std::fs::create_dir(&tmp).map_err(io_err(&tmp))?;
    let outcome = build(&tmp, cfg).and_then(|mut summary| {
        before_commit(&tmp)?;
        // rename(2) would silently replace an empty directory created meanwhile.
        if dir.symlink_metadata().is_ok() {
            return Err(SynthError::Exists(dir.to_owned()));
        }
        std::fs::rename(&tmp, dir).map_err(io_err(dir))?;
        summary.dir = dir.to_owned();
        Ok(summary)
    });
    if outcome.is_err() {
        let _ = std::fs::remove_dir_all(&tmp);
    }
    outcome
}

fn build(root: &Path, cfg: &SynthConfig) -> Result<SynthSummary, SynthError> {
    let start = Instant::now();
    let scene = tabletop(cfg.seed);
    let views = view_specs(cfg);
    let images = root.join("images");
    std::fs::create_dir(&images).map_err(io_err(&images))?;
    let (pinhole, stats) = render_all(&scene, &views, cfg, &images)?;

    let hold = root.join(format!("hold={}", cfg.hold));
    std::fs::File::create(&hold).map_err(io_err(&hold))?;

    let cam = &views[0].camera;
    let llff: Vec<LlffView> = views
        .iter()
        .zip(&stats)
        .map(|(v, s)| LlffView {
            world_from_camera: v.camera.world_from_camera,
            hwf: [f64::from(cam.height), f64::from(cam.width), cam.fx],
            near: s.depth_min,
            far: s.depth_max,
        })
        .collect();
    write_poses_bounds(&root.join("poses_bounds.npy"), &llff)?;

    let sparse = root.join("sparse").join("0");
    std::fs::create_dir_all(&sparse).map_err(io_err(&sparse))?;
    let model = build_model(&scene, &views, &pinhole, cfg.max_points, cfg.seed);
    write_txt(&model, &sparse)?;

    write_transforms(&root.join("transforms.json"), cfg, &views, &stats)?;
    let n_gauss = scene.gaussians.len();
    write_lens(
        &root.join("lens.json"),
        cfg,
        &views,
        &stats,
        n_gauss,
        model.points.len(),
    )?;

    let train_views = views.iter().filter(|v| v.split == Split::Train).count();
    Ok(SynthSummary {
        dir: root.to_owned(),
        views: views.len(),
        train_views,
        test_views: views.len() - train_views,
        width: cfg.width,
        height: cfg.height,
        focus_distances: views
            .iter()
            .map(|v| v.lens.map(|l| l.focus_distance))
            .collect(),
        gaussians: n_gauss,
        points: model.points.len(),
        elapsed: start.elapsed(),
    })
}

/// Renders one view, writes its PNG, and returns its pinhole render and statistics.
fn render_view(
    scene: &Scene,
    v: &ViewSpec,
    cfg: &SynthConfig,
    images: &Path,
) -> Result<(Image64, ViewStats), SynthError> {
    let pinhole = render(&scene.gaussians, &v.camera, scene.background);
    let color = match v.lens {
        Some(_) => render_thin_lens(
            &scene.gaussians,
            &v.camera,
            v.lens,
            cfg.lens_samples,
            scene.background,
            cfg.blur_space,
        ),
        None => pinhole.color.clone(),
    };
    write_png(
        &images.join(&v.name),
        v.camera.width,
        v.camera.height,
        &quantize(&color),
    )?;
    // A view that sees nothing still needs valid LLFF bounds: fall back to the focus range.
    let (lo, hi) = depth_bounds(&pinhole).unwrap_or((cfg.focus_range[0], cfg.focus_range[1] + 1.0));
    let coc_max_px = v.lens.map_or(0.0, |l| {
        l.coc_px(v.camera.fx, lo).max(l.coc_px(v.camera.fx, hi))
    });
    Ok((
        pinhole,
        ViewStats {
            depth_min: lo,
            depth_max: hi,
            coc_max_px,
        },
    ))
}

type Rendered = (Vec<Image64>, Vec<ViewStats>);
type Slot = Option<Result<(Image64, ViewStats), SynthError>>;

/// Renders all views on `cfg.threads` workers pulling view indices from a shared counter, so
/// the cheap sharp views fill the gaps between the expensive defocused ones.
fn render_all(
    scene: &Scene,
    views: &[ViewSpec],
    cfg: &SynthConfig,
    images: &Path,
) -> Result<Rendered, SynthError> {
    let workers = match cfg.threads {
        0 => std::thread::available_parallelism().map_or(1, usize::from),
        n => n,
    }
    .min(views.len());
    let next = AtomicUsize::new(0);
    let failed = AtomicBool::new(false);
    let slots: Mutex<Vec<Slot>> = Mutex::new((0..views.len()).map(|_| None).collect());
    std::thread::scope(|s| {
        for _ in 0..workers {
            s.spawn(|| {
                while !failed.load(Ordering::Relaxed) {
                    let i = next.fetch_add(1, Ordering::Relaxed);
                    let Some(v) = views.get(i) else { break };
                    let r = render_view(scene, v, cfg, images);
                    failed.fetch_or(r.is_err(), Ordering::Relaxed);
                    slots.lock().unwrap_or_else(|e| e.into_inner())[i] = Some(r);
                }
            });
        }
    });
    let slots = slots.into_inner().unwrap_or_else(|e| e.into_inner());
    let mut out = (
        Vec::with_capacity(views.len()),
        Vec::with_capacity(views.len()),
    );
    // Slots are empty only when a worker stopped after another view failed, and that
    // failure is in some slot, so skipping empties still returns it.
    for r in slots.into_iter().flatten() {
        let (img, st) = r?;
        out.0.push(img);
        out.1.push(st);
    }
    debug_assert_eq!(out.0.len(), views.len());
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_failure_at_the_last_moment_leaves_nothing_behind() {
        let tmp = tempfile::tempdir().unwrap();
        let ds = tmp.path().join("ds");
        let cfg = SynthConfig {
            views: 3,
            ..SynthConfig::tiny(2)
        };
        let mut seen = None;
        let err = generate(&ds, &cfg, |t| {
            // The dataset was complete in the temp directory when the failure struck.
            seen = Some(std::fs::read_dir(t.join("images")).unwrap().count());
            Err(SynthError::Config("injected".into()))
        })
        .unwrap_err();
        assert!(
            matches!(err, SynthError::Config(ref m) if m == "injected"),
            "{err}"
        );
        assert_eq!(seen, Some(3));
        assert_eq!(std::fs::read_dir(tmp.path()).unwrap().count(), 0);

        // The same call without the failure produces the dataset at `ds` and nothing else.
        generate(&ds, &cfg, |_| Ok(())).unwrap();
        let names: Vec<_> = std::fs::read_dir(tmp.path())
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names, ["ds"]);
    }
}
