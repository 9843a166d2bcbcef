//! `cocog lens SCENE`: the lens CoCoGaussian learned for every training photo, beside the
//! true one when the dataset the photos came from records it (a `transforms.json` with
//! `focus_distance_m` / `aperture_radius_m`, as the bench and the demo dataset have).

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use anyhow::{Context as _, Result, bail};
use cocog_pipeline::{Scene, Split};
use serde_json::{Value, json};

use crate::cli::{Global, LensArgs};

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
        let truth = truth.or_else(|| find_transforms(&Scene::resolve(dir, &learned[0].0.image)));
        let known = match &truth {
            Some(path) => read_truth(path)?,
            None => HashMap::new(),
        };
        let rows: Vec<Row> = learned
            .iter()
            .map(|(v, l)| {
                let t = known.get(&v.name);
                Row {
                    name: v.name.clone(),
                    focus: l.focus_distance,
                    aperture: l.aperture,
                    true_focus: t.and_then(|t| t.0),
                    true_aperture: t.and_then(|t| t.1),
                }
            })
            .collect();
        let mut errors: Vec<f64> = rows
            .iter()
            .filter_map(|r| r.true_focus.map(|t| rel(r.focus, t)))
            .collect();
        errors.sort_by(f64::total_cmp);
        let median = (!errors.is_empty()).then(|| errors[errors.len() / 2]);
        Ok(Self {
            scene: dir.to_owned(),
            rows,
            truth,
            median,
        })
    }

    pub fn table(&self) -> String {
        table(&self.rows, self.median, self.truth.as_deref())
    }

    pub fn to_json(&self) -> Value {
        json!({
            "scene": self.scene,
            "truth": self.truth,
            "views": self.rows.iter().map(|r| json!({
                "view": r.name,
                "focus_distance": r.focus,
                "aperture": r.aperture,
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

fn table(rows: &[Row], median: Option<f64>, truth: Option<&Path>) -> String {
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
    out += "focus: distance in focus from the camera centre (scene units)";
    if has_aperture {
        out += "; aperture: its diameter";
    }
    out += "\n";
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

/// A photo's true focus distance and aperture diameter, where the dataset records them.
type TrueLens = (Option<f64>, Option<f64>);

/// Per photo file name, its true lens.
fn read_truth(path: &Path) -> Result<HashMap<String, TrueLens>> {
    let frames = cocog_formats::nerf::read_transforms(path, None)
        .with_context(|| format!("reading the true lenses from {}", path.display()))?;
    Ok(frames
        .into_iter()
        .map(|f| {
            let lens = (f.focus_distance, f.aperture_radius.map(|r| 2.0 * r));
            (f.image_name(), lens)
        })
        .collect())
}
