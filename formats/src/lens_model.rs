//! `lens-model.safetensors`: a trained CoCoGaussian scene's lens model, what refocused
//! rendering needs besides the Gaussians: h_θ's weights, the compositor F's weights, and the
//! focus distance learned for every training view. f32 tensors plus string metadata, so
//! Python's `safetensors` reads it too.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use safetensors::{Dtype, SafeTensors, tensor::TensorView};

const FORMAT: &str = "cocog.lens-model";
const VERSION: &str = "1";
/// Metadata key and value marking h_θ's weights as trained with the `code` variant's gate and
/// offsets in scene units (since 76cd3bc; before, the max-depth frame spread the copies D²
/// times as wide). Lens models and checkpoints both carry it.
pub const COC_UNITS_KEY: &str = "coc_units";
pub const COC_UNITS: &str = "scene";

/// Why h_θ's weights of `variant`, in a file whose `coc_units` metadata is `units`, cannot be
/// used: a `code` variant file without the mark holds weights for the old meaning, which would
/// render and train wrong without a word. The other variants' weights kept their meaning.
pub fn coc_units_problem(variant: &str, units: Option<&str>) -> Option<String> {
    match units {
        Some(COC_UNITS) => None,
        None if variant != "code" => None,
        None => Some(format!(
            "a `code` variant file from before its offsets were in scene units (no metadata \
             `{COC_UNITS_KEY}`); its h_θ would spread the CoC copies wrongly: train it again"
        )),
        Some(other) => Some(format!(
            "metadata `{COC_UNITS_KEY}` = {other:?}; this cocog reads {COC_UNITS:?}"
        )),
    }
}

/// The lens model and the layout its weights follow.
#[derive(Clone, Debug, PartialEq)]
pub struct LensModel {
    /// `code` or `paper` (see `cocog train --help`).
    pub variant: String,
    /// CoC Gaussians per base Gaussian (M).
    pub copies: u32,
    /// Hidden width of h_θ.
    pub width: u32,
    /// Whether the copies' mean offset is subtracted.
    pub centred: bool,
    /// Whether the base set's scale and rotation are modulated like the copies'.
    pub modulate_base: bool,
    /// Hidden channels of F.
    pub compositor_channels: u32,
    /// Whether training reached F's start, so its weights are learned; renders average the
    /// CoC sets otherwise. Files from before it was recorded read as `true`.
    pub compositor_trained: bool,
    pub mlp: Vec<f32>,
    pub compositor: Vec<f32>,
    /// The frame h_θ works in: positions from `origin`, lengths over `scale`.
    pub origin: [f32; 3],
    pub scale: f32,
    /// Learned focus distance of every training view, in scene units, in the order of the
    /// scene's training views; empty if training stopped before the blurred phase.
    pub focus_distances: Vec<f32>,
    /// The lens variant's learned aperture of every training view, over `scale` (as h_θ
    /// uses it); empty for the other variants' files before the blurred phase.
    pub apertures: Vec<f32>,
}

#[derive(Debug, thiserror::Error)]
pub enum LensModelError {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{path}: not a cocog lens model: {why}")]
    Format { path: PathBuf, why: String },
}

impl LensModel {
    /// Writes the model to `path` (through a temporary file beside it, then a rename).
    pub fn save(&self, path: &Path) -> Result<(), LensModelError> {
        let origin = self.origin.to_vec();
        let scale = vec![self.scale];
        let tensors = [
            ("mlp", &self.mlp),
            ("compositor", &self.compositor),
            ("focus_distances", &self.focus_distances),
            ("apertures", &self.apertures),
            ("origin", &origin),
            ("scale", &scale),
        ];
        let views: Vec<(&str, TensorView<'_>)> = tensors
            .iter()
            .map(|(name, data)| {
                let view =
                    TensorView::new(Dtype::F32, vec![data.len()], bytemuck::cast_slice(data))
                        .expect("shape is the data's own length");
                (*name, view)
            })
            .collect();
        let meta = HashMap::from([
            ("format".to_owned(), FORMAT.to_owned()),
            ("version".to_owned(), VERSION.to_owned()),
            ("variant".to_owned(), self.variant.clone()),
            (COC_UNITS_KEY.to_owned(), COC_UNITS.to_owned()),
            ("copies".to_owned(), self.copies.to_string()),
            ("width".to_owned(), self.width.to_string()),
            ("centred".to_owned(), self.centred.to_string()),
            ("modulate_base".to_owned(), self.modulate_base.to_string()),
            (
                "compositor_channels".to_owned(),
                self.compositor_channels.to_string(),
            ),
            (
                "compositor_trained".to_owned(),
                self.compositor_trained.to_string(),
            ),
        ]);
        let io = |source| LensModelError::Io {
            path: path.to_path_buf(),
            source,
        };
        let name = path
            .file_name()
            .map_or_else(|| "lens-model".into(), |n| n.to_string_lossy().into_owned());
        let tmp = path.with_file_name(format!(".{name}.tmp"));
        safetensors::serialize_to_file(views, Some(meta), &tmp)
            .map_err(|e| io(std::io::Error::other(e)))?;
        std::fs::rename(&tmp, path).map_err(io)
    }

    /// Reads and checks a model written by `save`.
    pub fn load(path: &Path) -> Result<Self, LensModelError> {
        let data = std::fs::read(path).map_err(|source| LensModelError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        let fail = |why: String| LensModelError::Format {
            path: path.to_path_buf(),
            why,
        };
        let st = SafeTensors::deserialize(&data).map_err(|e| {
            fail(crate::safetensors_layout::explain_layout(&data).unwrap_or_else(|| e.to_string()))
        })?;
        let (_, header) = SafeTensors::read_metadata(&data).map_err(|e| fail(e.to_string()))?;
        let meta = header.metadata().clone().unwrap_or_default();
        let text = |key: &str| {
            meta.get(key)
                .cloned()
                .ok_or_else(|| fail(format!("metadata has no `{key}`")))
        };
        let number = |key: &str| -> Result<u32, LensModelError> {
            let t = text(key)?;
            t.parse()
                .map_err(|_| fail(format!("metadata `{key}` = {t:?} is not a count")))
        };
        if text("format")? != FORMAT {
            return Err(fail("metadata `format` is not cocog.lens-model".into()));
        }
        let version = text("version")?;
        if version != VERSION {
            return Err(fail(format!(
                "version {version}; this cocog reads version {VERSION}"
            )));
        }
        let floats = |name: &str| -> Result<Vec<f32>, LensModelError> {
            let t = st
                .tensor(name)
                .map_err(|_| fail(format!("tensor `{name}` is missing")))?;
            if t.dtype() != Dtype::F32 || t.data().len() % 4 != 0 {
                return Err(fail(format!("tensor `{name}` is not f32")));
            }
            let v: Vec<f32> = bytemuck::pod_collect_to_vec(t.data());
            if let Some(bad) = v.iter().find(|x| !x.is_finite()) {
                return Err(fail(format!("tensor `{name}` holds {bad}")));
            }
            Ok(v)
        };
        let flag = |key: &str| match text(key)?.as_str() {
            "true" => Ok(true),
            "false" => Ok(false),
            other => Err(fail(format!("metadata `{key}` = {other:?}"))),
        };
        let variant = text("variant")?;
        if let Some(why) = coc_units_problem(&variant, meta.get(COC_UNITS_KEY).map(String::as_str))
        {
            return Err(fail(why));
        }
        let centred = flag("centred")?;
        let modulate_base = flag("modulate_base")?;
        let compositor_trained = match meta.get("compositor_trained") {
            Some(_) => flag("compositor_trained")?,
            None => true,
        };
        let origin = floats("origin")?;
        let scale = floats("scale")?;
        let (origin, scale) = match (&origin[..], &scale[..]) {
            (&[x, y, z], &[s]) if s > 0.0 => ([x, y, z], s),
            _ => {
                return Err(fail(format!(
                    "`origin` {origin:?} and `scale` {scale:?}: expected 3 numbers and one \
                     positive number"
                )));
            }
        };
        let model = Self {
            origin,
            scale,
            apertures: floats("apertures")?,
            variant,
            copies: number("copies")?,
            width: number("width")?,
            centred,
            modulate_base,
            compositor_channels: number("compositor_channels")?,
            compositor_trained,
            mlp: floats("mlp")?,
            compositor: floats("compositor")?,
            focus_distances: floats("focus_distances")?,
        };
        if let Some(d) = model.focus_distances.iter().find(|d| **d <= 0.0) {
            return Err(fail(format!(
                "a focus distance is {d}; they must be positive"
            )));
        }
        Ok(model)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn model() -> LensModel {
        LensModel {
            variant: "code".into(),
            copies: 4,
            width: 64,
            centred: true,
            modulate_base: true,
            compositor_channels: 16,
            compositor_trained: false,
            mlp: vec![0.5, -0.25, 1e-3],
            compositor: vec![2.0; 5],
            origin: [0.1, 0.2, -0.3],
            scale: 3.5,
            focus_distances: vec![0.8, 1.25],
            apertures: vec![0.01, 0.02],
        }
    }

    #[test]
    fn a_model_round_trips() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("lens-model.safetensors");
        model().save(&path).unwrap();
        assert_eq!(LensModel::load(&path).unwrap(), model());
        assert!(!dir.path().join(".lens-model.safetensors.tmp").exists());
    }

    #[test]
    fn bad_files_are_named_with_the_reason() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("lens-model.safetensors");
        std::fs::write(&path, b"nope").unwrap();
        let e = LensModel::load(&path).unwrap_err().to_string();
        assert!(e.contains("lens-model.safetensors") && e.contains("not a cocog lens model"));
        let mut m = model();
        m.focus_distances[1] = -1.0;
        m.save(&path).unwrap();
        let e = LensModel::load(&path).unwrap_err().to_string();
        assert!(e.contains("focus distance is -1"), "{e}");
        m.focus_distances[1] = f32::NAN;
        m.save(&path).unwrap();
        let e = LensModel::load(&path).unwrap_err().to_string();
        assert!(e.contains("focus_distances") && e.contains("NaN"), "{e}");
    }

    /// `path` written again with its metadata changed by `edit`.
    fn rewrite_meta(path: &Path, edit: impl FnOnce(&mut HashMap<String, String>)) {
        let data = std::fs::read(path).unwrap();
        let st = SafeTensors::deserialize(&data).unwrap();
        let (_, header) = SafeTensors::read_metadata(&data).unwrap();
        let mut meta = header.metadata().clone().unwrap();
        edit(&mut meta);
        let views: Vec<_> = st.tensors();
        safetensors::serialize_to_file(views, Some(meta), path).unwrap();
    }

    #[test]
    fn a_code_variant_model_without_its_units_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("lens-model.safetensors");
        model().save(&path).unwrap();
        rewrite_meta(&path, |m| {
            m.remove("coc_units");
        });
        let e = LensModel::load(&path).unwrap_err().to_string();
        assert!(
            e.contains("coc_units") && e.contains("train it again"),
            "{e}"
        );
        // The other variants' weights kept their meaning, so their older files still load.
        let mut paper = model();
        paper.variant = "paper".into();
        paper.save(&path).unwrap();
        rewrite_meta(&path, |m| {
            m.remove("coc_units");
        });
        assert_eq!(LensModel::load(&path).unwrap(), paper);
        rewrite_meta(&path, |m| {
            m.insert("coc_units".into(), "max-depth".into());
        });
        let e = LensModel::load(&path).unwrap_err().to_string();
        assert!(e.contains("\"max-depth\""), "{e}");
    }
}
