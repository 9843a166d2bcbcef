//! `ingest-photos`: a folder of photos in, a scene out, by running COLMAP (feature extraction,
//! matching, mapping with the lens held, a bundle adjustment that refines the lens, and
//! undistortion where the lens needs it) in `colmap/` inside the output.
//! COLMAP's log is kept there, its progress is relayed, and every photo that did not make it
//! into the scene is reported with COLMAP's reason.

mod colmap;
mod database;
mod mapping;
mod model;
mod settings;

use std::collections::HashSet;
use std::path::{Path, PathBuf};

use cocog_formats::images::list_images;
use cocog_pipeline::{Context, StageError, StageRequest};
use serde_json::{Value, json};

use crate::build::{Settings, build_scene};
use crate::input_error;
use crate::readers::from_colmap_model;
use colmap::{Args, Colmap};
pub(crate) use settings::options;
use settings::{Matcher, PhotoSettings};

/// Rename, or copy and remove where the two are on different file systems.
fn move_file(from: &Path, to: &Path) -> Result<(), StageError> {
    if std::fs::rename(from, to).is_ok() {
        return Ok(());
    }
    std::fs::copy(from, to).map_err(|e| StageError::io(to, e))?;
    std::fs::remove_file(from).map_err(|e| StageError::io(from, e))
}

/// The photos: `DIR/images/` when DIR holds that folder (a dataset, with its `hold=N` marker in
/// DIR), else DIR itself.
fn photo_dir(dir: &Path) -> PathBuf {
    let sub = dir.join("images");
    let direct = list_images(dir).map(|v| v.len()).unwrap_or(0);
    if direct == 0 && sub.is_dir() {
        sub
    } else {
        dir.to_path_buf()
    }
}

pub(crate) fn run(
    req: &StageRequest,
    base: &Settings,
    ctx: &dyn Context,
) -> Result<Value, StageError> {
    let s = PhotoSettings::from_request(req)?;
    let dataset = &req.input;
    let photos = photo_dir(dataset);
    let n = list_images(&photos).map_err(input_error)?.len();
    if n < 3 {
        return Err(StageError::Input(format!(
            "{}: found {n} photos (png, jpg, jpeg); structure from motion needs at least 3, \
             taken from different positions with overlapping views",
            photos.display()
        )));
    }
    let work = req.output.join("colmap");
    std::fs::create_dir_all(&work).map_err(|e| StageError::io(&work, e))?;
    let kept_log = work.join("colmap.log");
    let log = s.log.clone().unwrap_or_else(|| kept_log.clone());
    let cm = Colmap::find(s.colmap.as_deref(), log.clone())?;
    // A fresh log per run (a failed run's log beside the output is replaced, not appended to),
    // created only once COLMAP is known to run, so a missing COLMAP leaves no empty log behind.
    std::fs::write(&log, b"").map_err(|e| StageError::io(&log, e))?;
    let matcher = s.matcher.resolve(n, s.vocab_tree.is_some());
    ctx.info(&format!(
        "{}: {n} photos in {}, {} matching; log: {}",
        cm.version,
        photos.display(),
        matcher.name(),
        log.display()
    ));
    let db = work.join("database.db");
    let gpu = u8::from(s.gpu);
    let mut extract = Args::new("feature_extractor")
        .arg("database_path", db.display())
        .arg("image_path", photos.display())
        .arg("ImageReader.camera_model", &s.camera_model)
        .arg("ImageReader.single_camera", u8::from(!s.camera_per_image))
        .tune("SiftExtraction.use_gpu", gpu)
        .tune("FeatureExtraction.use_gpu", gpu)
        .tune("SiftExtraction.max_num_features", s.max_features)
        .tune("SiftExtraction.domain_size_pooling", u8::from(s.dsp));
    if let Some(f) = s.focal_factor {
        extract = extract.arg("ImageReader.default_focal_length_factor", f);
    }
    cm.run(extract, "extract features", ctx)?;
    let exif = colmap::tail(&log, usize::MAX)
        .lines()
        .filter(|l| l.contains("Focal Length:") && l.contains("(Prior)"))
        .count();
    let mut m = Args::new(matcher.command())
        .arg("database_path", db.display())
        .tune("SiftMatching.use_gpu", gpu)
        .tune("FeatureMatching.use_gpu", gpu)
        .tune("SiftMatching.max_ratio", s.max_ratio)
        .tune("SiftMatching.guided_matching", u8::from(s.guided))
        // Smaller blocks than COLMAP's 50: the progress bar moves on small photo sets.
        .tune("ExhaustiveMatching.block_size", 20);
    if let (Matcher::VocabTree, Some(tree)) = (matcher, &s.vocab_tree) {
        m = m.arg("VocabTreeMatching.vocab_tree_path", tree.display());
    }
    cm.run(m, "match features", ctx)?;
    let need = s.min_registered.unwrap_or_else(|| (n.div_ceil(2)).max(3));
    let mapper = mapping::Mapper {
        cm: &cm,
        settings: &s,
        db: &db,
        photos: &photos,
        photos_n: n,
        ctx,
    };
    let (mut models, intrinsics) = mapper.map(&work, need)?;

    let evidence = database::read(&db)?;
    let focal_prior = database::focal_prior(&db)?;
    let all: Vec<String> = evidence.keys().cloned().collect();
    if models.is_empty() {
        let reasons = all
            .iter()
            .map(|name| {
                let why = database::reason(name, &evidence, &HashSet::new(), false);
                format!("  {name}: {why}")
            })
            .collect::<Vec<_>>()
            .join("\n");
        return Err(StageError::Input(format!(
            "COLMAP could not reconstruct {}: no model came out of mapping.\n{reasons}\nlog: {}",
            photos.display(),
            log.display()
        )));
    }
    let mut kept = models.remove(0);
    let kept_names: HashSet<String> = kept.model.images.iter().map(|i| i.name.clone()).collect();
    let elsewhere: HashSet<String> = models
        .iter()
        .flat_map(|m| m.model.images.iter().map(|i| i.name.clone()))
        .collect();
    let dropped: Vec<(String, String)> = all
        .iter()
        .filter(|n| !kept_names.contains(*n))
        .map(|name| {
            let why = database::reason(name, &evidence, &kept_names, elsewhere.contains(name));
            (name.clone(), why)
        })
        .collect();
    let listing = dropped
        .iter()
        .map(|(n, why)| format!("  {n}: {why}"))
        .collect::<Vec<_>>()
        .join("\n");
    if kept_names.len() < need {
        return Err(StageError::Input(format!(
            "COLMAP registered {} of {n} photos in its largest model; at least {need} are needed \
             (--min-registered). Not registered:\n{listing}\nlog: {}",
            kept_names.len(),
            log.display()
        )));
    }
    if !models.is_empty() {
        ctx.warn(&format!(
            "COLMAP made {} separate models; keeping the largest ({} photos, {})",
            models.len() + 1,
            kept_names.len(),
            kept.dir.display()
        ));
    }
    if !dropped.is_empty() {
        ctx.warn(&format!(
            "{} of {n} photos are not in the scene:\n{listing}",
            dropped.len()
        ));
    }

    if intrinsics == mapping::Intrinsics::HeldThenRefined {
        mapping::refine(&cm, &mut kept, &work, ctx)?;
    }
    let mut mapped = kept.model;
    let (distortion, undistort) = model::drop_small_distortion(&mut mapped);
    let (final_model, final_dir, images) = if undistort {
        let out = work.join("undistorted");
        cm.run(
            Args::new("image_undistorter")
                .arg("image_path", photos.display())
                .arg("input_path", kept.dir.display())
                .arg("output_path", out.display())
                .arg("output_type", "COLMAP"),
            "undistort",
            ctx,
        )?;
        let dir = out.join("sparse");
        let m = cocog_formats::colmap::read_model(&dir).map_err(input_error)?;
        (m, dir, out.join("images"))
    } else {
        (mapped, kept.dir, photos)
    };
    let cam = &final_model.cameras[0];
    let focal = cam.pinhole().map(|p| p.fx).unwrap_or(f64::NAN);
    let data = from_colmap_model(&final_model, &final_dir, &images, dataset)?;
    let (_, mut summary) = build_scene(dataset, data, base, &req.output, ctx)?;
    if log != kept_log {
        move_file(&log, &kept_log)?;
    }
    summary["colmap"] = json!({
        "version": cm.version,
        "matcher": matcher.name(),
        "photos": n,
        "registered": kept_names.len(),
        "models": models.len() + 1,
        "not_registered": dropped.iter().map(|(n, why)| json!({"image": n, "reason": why}))
            .collect::<Vec<_>>(),
        "camera_model": s.camera_model,
        "intrinsics": intrinsics.describe(),
        "cameras": final_model.cameras.len(),
        "focal_px": focal,
        "focal_from_exif": exif,
        "focal_prior_px": focal_prior,
        "distortion_px": distortion,
        "undistorted": undistort,
        "log": "colmap/colmap.log",
    });
    Ok(summary)
}
