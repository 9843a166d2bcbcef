//! `cocog lens SCENE`: the lens CoCoGaussian learned for every training photo, beside the
//! true one when the dataset the photos came from records it (a `transforms.json` with
//! `focus_distance_m` / `aperture_radius_m`, as the bench and the demo dataset have). The
//! scene's units are measured against the truth's metres first (lens_units.rs).

use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};

use anyhow::{Context as _, Result, bail};
use cocog_pipeline::{Scene, Split};
use serde_json::{Value, json};

use crate::cli::{Global, LensArgs};
use crate::lens_units::{MIN_PAIRS, UnitScale, centre, median, unit_scale};

/// One training photo's learned and (when known) true lens.
struct Row {
    name: String,
    focus: f64,
    aperture: Option<f64>,
    true_focus: Option<f64>,
    true_aperture: Option<f64>,
}

/// Every training photo's learned lens, beside the truth where the dataset has it.
pub struct LensReport {
    scene: PathBuf,
    rows: Vec<Row>,
    truth: Option<PathBuf>,
    /// The scene unit measured in the truth's metres, where the two camera layouts allow.
    units: Option<UnitScale>,
    /// Median relative focus error over the photos with a known focus.
    pub median: Option<f64>,
}

impl LensReport {
    /// Reads the lenses of the scene in `dir`; `truth` overrides the transforms.json found
    /// beside its photos.
    pub fn read(dir: &Path, truth: Option<PathBuf>) -> Result<Self> {
        let mut scene = Scene::load(dir).with_context(|| format!("{}", dir.display()))?;
        scene.rebase(dir)?;
        let learned: Vec<_> = scene
            .views
            .iter()
            .filter(|v| v.split == Split::Train)
            .filter_map(|v| v.lens.as_ref().map(|l| (v, l)))
            .collect();
        if learned.is_empty() {
            bail!(
                "{}: no training photo has a learned lens; train with --method cocog (past \
                 --blur-start) to learn one",
                dir.display()
            );
        }
        let truth = truth
            .or_else(|| find_transforms(&Scene::resolve(dir, &learned[0].0.image)))
            .or_else(|| ingested_transforms(&scene));
        let (known, truth_centres) = match &truth {
            Some(path) => read_truth(path)?,
            None => Default::default(),
        };
        let keys = unique_keys(scene.views.iter().map(|v| v.name.as_str()));
        let key = |name: &str| Some(photo_key(name)).filter(|k| keys.contains(k));
        let scene_centres = scene
            .views
            .iter()
            .filter_map(|v| Some((key(&v.name)?, centre(&v.world_from_camera))))
            .collect();
        // Units matter only where there is a true lens to compare with.
        let has_lens = known.values().any(|t| t.0.is_some() || t.1.is_some());
        let units = has_lens
            .then(|| unit_scale(&scene_centres, &truth_centres))
            .flatten();
        // Without a consistent measure the units are taken as metres, and the table says so.
        let metres = metres_of(units);
        let rows: Vec<Row> = learned
            .iter()
            .map(|(v, l)| {
                let t = key(&v.name).and_then(|k| known.get(&k));
                Row {
                    name: v.name.clone(),
                    focus: metres * l.focus_distance,
                    // The sign of a learned aperture is a symmetry (it flips the copies'
                    // offsets, which h_θ's directions absorb); the diameter is its magnitude.
                    aperture: l.aperture.map(|a| metres * a.abs()),
                    true_focus: t.and_then(|t| t.0),
                    true_aperture: t.and_then(|t| t.1),
                }
            })
            .collect();
        let mut errors: Vec<f64> = rows
            .iter()
            .filter_map(|r| r.true_focus.map(|t| rel(r.focus, t)))
            .collect();
        let median = (!errors.is_empty()).then(|| median(&mut errors));
        Ok(Self {
            scene: dir.to_owned(),
            rows,
            truth,
            units,
            median,
        })
    }

    pub fn table(&self) -> String {
        let has_truth = self.rows.iter().any(|r| r.true_focus.is_some());
        let units = has_truth.then(|| units_line(self.units));
        table(&self.rows, self.median, self.truth.as_deref(), units)
    }

    pub fn to_json(&self) -> Value {
        let m = metres_of(self.units);
        // Metre values only where the scene unit was measured.
        let measured = self.units.is_some_and(|u| u.consistent());
        json!({
            "scene": self.scene,
            "truth": self.truth,
            "metres_per_scene_unit": self.units.map(|u| u.metres_per_unit),
            "camera_pairs": self.units.map(|u| u.pairs),
            "camera_layout_spread": self.units.map(|u| u.spread),
            "units_compared_as": m,
            "views": self.rows.iter().map(|r| json!({
                "view": r.name,
                "focus_distance": r.focus / m,
                "aperture": r.aperture.map(|a| a / m),
                "focus_distance_m": measured.then_some(r.focus),
                "aperture_m": r.aperture.filter(|_| measured),
                "true_focus_distance": r.true_focus,
                "true_aperture": r.true_aperture,
                "focus_relative_error": r.true_focus.map(|t| rel(r.focus, t)),
            })).collect::<Vec<Value>>(),
            "median_focus_relative_error": self.median,
        })
    }
}

fn rel(a: f64, b: f64) -> f64 {
    (a - b).abs() / b
}

pub fn run(a: &LensArgs, g: &Global) -> Result<()> {
    let report = LensReport::read(&a.scene, a.truth.clone())?;
    if g.json {
        println!("{}", serde_json::to_string_pretty(&report.to_json())?);
    } else {
        print!("{}", report.table());
    }
    Ok(())
}

fn table(rows: &[Row], median: Option<f64>, truth: Option<&Path>, units: Option<String>) -> String {
    let has_aperture = rows.iter().any(|r| r.aperture.is_some());
    let has_truth = rows.iter().any(|r| r.true_focus.is_some());
    let mut out = String::from("view          focus");
    if has_truth {
        out += "     true   error";
    }
    if has_aperture {
        out += "   aperture";
        if has_truth {
            out += "     true";
        }
    }
    out += "\n";
    let cell = |v: Option<f64>| v.map_or("       -".to_owned(), |v| format!("{v:>8.4}"));
    for r in rows {
        out += &format!("{:<12}{:>8.4}", r.name, r.focus);
        if has_truth {
            let err = r.true_focus.map_or("      -".to_owned(), |t| {
                format!("{:>6.1}%", 100.0 * (r.focus - t) / t)
            });
            out += &format!(" {} {err}", cell(r.true_focus));
        }
        if has_aperture {
            out += &format!("   {}", cell(r.aperture));
            if has_truth {
                out += &format!(" {}", cell(r.true_aperture));
            }
        }
        out += "\n";
    }
    let unit = if has_truth { "metres" } else { "scene units" };
    out += &format!("focus: distance in focus from the camera centre ({unit})");
    if has_aperture {
        out += "; aperture: its diameter";
    }
    out += "\n";
    out += units.as_deref().unwrap_or_default();
    match (median, truth) {
        (Some(m), Some(t)) => {
            out += &format!(
                "median relative focus error {:.1}% over {} photos (truth: {})\n",
                100.0 * m,
                rows.iter().filter(|r| r.true_focus.is_some()).count(),
                t.display()
            );
        }
        _ => out += "no true lens known (pass --truth transforms.json if the dataset has one)\n",
    }
    out
}

/// `transforms.json` beside the folder holding a view's photo (`DATASET/images/x.png`).
fn find_transforms(image: &Path) -> Option<PathBuf> {
    let dataset = image.parent()?.parent()?;
    let t = dataset.join("transforms.json");
    t.is_file().then_some(t)
}

/// `transforms.json` in the dataset the scene was ingested from: a downscaled ingest keeps its
/// own resampled photos, so the photos' folder no longer leads to the dataset.
fn ingested_transforms(scene: &Scene) -> Option<PathBuf> {
    let ingest = scene
        .history
        .iter()
        .find(|h| h.stage.starts_with("ingest"))?;
    // A relative input was relative to wherever ingest ran, which this process cannot know.
    let dataset = Path::new(&ingest.input);
    let t = dataset.join("transforms.json");
    (dataset.is_absolute() && t.is_file()).then_some(t)
}

/// Metres per scene unit as the comparison uses them (1 where unmeasured).
fn metres_of(units: Option<UnitScale>) -> f64 {
    units
        .filter(UnitScale::consistent)
        .map_or(1.0, |u| u.metres_per_unit)
}

/// A photo's key on both sides: its file name without folders or an image extension. Scenes
/// keep a dataset's subfolders in view names, transforms.json paths carry theirs, and the same
/// photo is often a `.JPG` in one and a `.png` (or no extension) in the other. Only image
/// extensions are dropped, so `frame.0001` stays itself.
fn photo_key(name: &str) -> String {
    const IMAGE: [&str; 8] = ["png", "jpg", "jpeg", "exr", "webp", "tif", "tiff", "bmp"];
    let path = Path::new(name);
    let image = path
        .extension()
        .is_some_and(|e| IMAGE.contains(&e.to_string_lossy().to_ascii_lowercase().as_str()));
    let key = if image {
        path.file_stem()
    } else {
        path.file_name()
    };
    key.map_or_else(|| name.to_owned(), |n| n.to_string_lossy().into_owned())
}

/// The keys that name exactly one of `names` (a key shared by two photos names neither).
fn unique_keys<'a>(names: impl Iterator<Item = &'a str>) -> HashSet<String> {
    let mut seen: HashMap<String, usize> = HashMap::new();
    for n in names {
        *seen.entry(photo_key(n)).or_insert(0) += 1;
    }
    seen.into_iter()
        .filter_map(|(k, c)| (c == 1).then_some(k))
        .collect()
}

/// How the scene's units were related to the truth's metres.
fn units_line(units: Option<UnitScale>) -> String {
    match units {
        Some(u) if u.consistent() => format!(
            "scene unit = {:.4} m, measured by {} camera pairs (spread {:.1}%); learned values \
             shown in metres\n",
            u.metres_per_unit,
            u.pairs,
            100.0 * u.spread
        ),
        Some(u) if u.pairs < MIN_PAIRS => format!(
            "warning: only {} camera pair(s) in both the scene and the truth, too few to check \
             that they agree; scene units taken as metres\n",
            u.pairs
        ),
        Some(u) => format!(
            "warning: the scene's cameras and the truth's are not one similarity apart (pairs \
             differ by {:.1}% in scale, more than {:.0}%); scene units taken as metres, so the \
             errors may mean nothing\n",
            100.0 * u.spread,
            100.0 * crate::lens_units::MAX_SPREAD
        ),
        None => "warning: fewer than two photos have distinct poses in both the scene and the \
                 truth; scene units taken as metres\n"
            .to_owned(),
    }
}

/// A photo's true focus distance and aperture diameter, where the dataset records them.
type TrueLens = (Option<f64>, Option<f64>);

/// Per photo file name, its true lens and camera centre (metres).
type Truth = (HashMap<String, TrueLens>, HashMap<String, [f64; 3]>);

fn read_truth(path: &Path) -> Result<Truth> {
    let frames = cocog_formats::nerf::read_transforms(path, None)
        .with_context(|| format!("reading the true lenses from {}", path.display()))?;
    // A name in two frames (Blender's train/r_0 and test/r_0) names neither for sure.
    let keys = unique_keys(frames.iter().map(|f| f.file_path.as_str()));
    let unique: Vec<_> = frames
        .into_iter()
        .filter_map(|f| {
            let k = photo_key(&f.file_path);
            keys.contains(&k).then_some((k, f))
        })
        .collect();
    let centres = unique
        .iter()
        .map(|(k, f)| (k.clone(), centre(&f.world_from_camera)))
        .collect();
    let lenses = unique
        .into_iter()
        .map(|(k, f)| (k, (f.focus_distance, f.aperture_radius.map(|r| 2.0 * r))))
        .collect();
    Ok((lenses, centres))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_ingested_dataset_gives_the_truth_when_the_photos_were_resampled() {
        let data = tempfile::tempdir().unwrap();
        let mut scene = Scene::default();
        scene.history.push(cocog_pipeline::scene::HistoryEntry {
            stage: "ingest-llff".into(),
            provider: "built-in".into(),
            input: data.path().display().to_string(),
            options: serde_json::json!({"downscale": 4}),
            resolved: None,
            cocog_version: "test".into(),
            finished_at: 0,
        });
        assert_eq!(ingested_transforms(&scene), None);
        std::fs::write(data.path().join("transforms.json"), "{}").unwrap();
        assert_eq!(
            ingested_transforms(&scene),
            Some(data.path().join("transforms.json"))
        );
        // Relative to wherever ingest ran: not guessed at, though from this test's folder (the
        // crate's) it names a dataset with a transforms.json where ../shared is beside.
        scene.history[0].input = "../../shared/bench/defocus-dev/dev-table".into();
        assert_eq!(ingested_transforms(&scene), None);
    }
}
