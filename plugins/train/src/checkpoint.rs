//! Everything a run needs to continue bit-for-bit where it stopped, and its on-disk form.
//!
//! One safetensors file: every GPU buffer of the run as an f32 tensor, and the scalars (step,
//! generator states, the view stack) in the header's string metadata. safetensors because
//! the parameters and moments are large flat f32 arrays and other tools (Python's
//! `safetensors`, numpy) read it without cocog.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use cocog_engine::GaussianParams;
use cocog_formats::lens_model::{COC_UNITS, COC_UNITS_KEY, coc_units_problem};
use safetensors::{Dtype, SafeTensors, tensor::TensorView};

/// File name inside a checkpoint directory.
pub const CHECKPOINT_FILE: &str = "state.safetensors";
const FORMAT: &str = "cocog.checkpoint";
const VERSION: &str = "1";

/// Adam's first and second moments of one parameter group.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MomentState {
    pub m: Vec<f32>,
    pub v: Vec<f32>,
}

/// CoCoGaussian's learned lens model and its optimiser state: h_θ, the compositor F and the
/// focus distances, each with Adam's moments.
#[derive(Clone, Debug, PartialEq)]
pub struct CocCheckpoint {
    /// `code` or `paper`, M, h_θ's width, whether the copies are centred, F's channels: what
    /// the weights' layout depends on, checked on resume.
    pub variant: String,
    pub copies: u32,
    pub width: u32,
    pub centred: bool,
    pub modulate_base: bool,
    pub compositor_channels: u32,
    /// The blur and compositor starts the run trained with, kept on resume unless given
    /// (they are fitted to the run's length, which a resume may change); `None` in older
    /// checkpoints.
    pub starts: Option<[u32; 2]>,
    pub mlp: Vec<f32>,
    pub mlp_moments: MomentState,
    pub compositor: Vec<f32>,
    pub compositor_moments: MomentState,
    /// Per training view d_F / `focus_scale`, once the blurred phase has started.
    pub focus: Option<FocusState>,
}

/// The learned lenses: d_F of view i is `values[i] × scale` (scene units), the lens
/// variant's aperture `apertures[i] × scale`; h_θ sees positions from `origin` over `scale`.
#[derive(Clone, Debug, PartialEq)]
pub struct FocusState {
    pub values: Vec<f32>,
    pub moments: MomentState,
    pub apertures: Vec<f32>,
    pub aperture_moments: MomentState,
    pub scale: f32,
    pub origin: [f32; 3],
}

/// A trainer's complete state between two iterations.
#[derive(Clone, Debug, PartialEq)]
pub struct TrainState {
    /// Iterations completed.
    pub iteration: u32,
    /// The iteration whose point addition last rebuilt the Gaussians' Adam state (0: none):
    /// their bias correction counts steps from there. `None` in checkpoints older than it
    /// (the trainer then infers it from the run's schedule).
    pub adam_origin: Option<u32>,
    /// Train views of the run; a resume must train on the same list.
    pub views: u32,
    /// Image shrink factor of the run, checked on resume (the state is resolution-specific
    /// only through the learned scales, but mixing would silently change the experiment).
    pub downscale: u32,
    pub params: GaussianParams,
    /// Groups in parameter order: means, log-scales, quaternions, opacity logits, SH.
    pub moments: [MomentState; 5],
    /// Densification statistics: Σ‖∇mean2d‖ and visible count per Gaussian.
    pub grad_accum: Vec<f32>,
    pub grad_denom: Vec<f32>,
    /// Generator state of the split sampler.
    pub rng: u64,
    /// The view order: its generator state and the views left in this epoch.
    pub order_rng: u64,
    pub order_stack: Vec<u32>,
    /// CoCoGaussian's lens model (`--method cocog` only).
    pub coc: Option<CocCheckpoint>,
}

const GROUPS: [&str; 5] = ["means", "log_scales", "quats", "opacity_logits", "sh"];

#[derive(Debug, thiserror::Error)]
pub enum CheckpointError {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{path}: not a cocog checkpoint: {why}")]
    Format { path: PathBuf, why: String },
}

fn bytes(v: &[f32]) -> &[u8] {
    bytemuck::cast_slice(v)
}

impl TrainState {
    /// Writes `dir/state.safetensors` (the caller makes `dir` appear atomically).
    pub fn save(&self, dir: &Path) -> Result<PathBuf, CheckpointError> {
        let path = dir.join(CHECKPOINT_FILE);
        let io = |source| CheckpointError::Io {
            path: path.clone(),
            source,
        };
        std::fs::create_dir_all(dir).map_err(io)?;
        let p = &self.params;
        let flat = |v: &[[f32; 3]]| v.as_flattened().to_vec();
        let mut tensors: Vec<(String, Vec<f32>)> = vec![
            ("params.means".into(), flat(&p.means)),
            ("params.log_scales".into(), flat(&p.log_scales)),
            ("params.quats".into(), p.quats.as_flattened().to_vec()),
            ("params.opacity_logits".into(), p.opacity_logits.clone()),
            ("params.sh".into(), p.sh.clone()),
            ("stats.grad_accum".into(), self.grad_accum.clone()),
            ("stats.grad_denom".into(), self.grad_denom.clone()),
        ];
        for (name, m) in GROUPS.iter().zip(&self.moments) {
            tensors.push((format!("adam.{name}.m"), m.m.clone()));
            tensors.push((format!("adam.{name}.v"), m.v.clone()));
        }
        let mut coc_meta = Vec::new();
        if let Some(c) = &self.coc {
            tensors.push(("coc.mlp".into(), c.mlp.clone()));
            tensors.push(("adam.coc_mlp.m".into(), c.mlp_moments.m.clone()));
            tensors.push(("adam.coc_mlp.v".into(), c.mlp_moments.v.clone()));
            tensors.push(("coc.compositor".into(), c.compositor.clone()));
            tensors.push((
                "adam.coc_compositor.m".into(),
                c.compositor_moments.m.clone(),
            ));
            tensors.push((
                "adam.coc_compositor.v".into(),
                c.compositor_moments.v.clone(),
            ));
            coc_meta.extend([
                ("coc_variant", c.variant.clone()),
                (COC_UNITS_KEY, COC_UNITS.to_owned()),
                ("coc_copies", c.copies.to_string()),
                ("coc_width", c.width.to_string()),
                ("coc_centred", c.centred.to_string()),
                ("coc_modulate_base", c.modulate_base.to_string()),
                ("coc_compositor_channels", c.compositor_channels.to_string()),
            ]);
            if let Some([blur, composite]) = c.starts {
                coc_meta.extend([
                    ("coc_blur_start", blur.to_string()),
                    ("coc_composite_start", composite.to_string()),
                ]);
            }
            if let Some(f) = &c.focus {
                tensors.push(("coc.focus".into(), f.values.clone()));
                tensors.push(("adam.coc_focus.m".into(), f.moments.m.clone()));
                tensors.push(("adam.coc_focus.v".into(), f.moments.v.clone()));
                tensors.push(("coc.apertures".into(), f.apertures.clone()));
                tensors.push(("adam.coc_apertures.m".into(), f.aperture_moments.m.clone()));
                tensors.push(("adam.coc_apertures.v".into(), f.aperture_moments.v.clone()));
                tensors.push(("coc.origin".into(), f.origin.to_vec()));
                coc_meta.push(("coc_focus_scale", f.scale.to_string()));
            }
        }
        let views: Vec<(String, TensorView<'_>)> = tensors
            .iter()
            .map(|(name, data)| {
                let view = TensorView::new(Dtype::F32, vec![data.len()], bytes(data))
                    .expect("shape is the data's own length");
                (name.clone(), view)
            })
            .collect();
        let stack: Vec<String> = self.order_stack.iter().map(u32::to_string).collect();
        let mut meta = HashMap::from([
            ("format".to_owned(), FORMAT.to_owned()),
            ("version".to_owned(), VERSION.to_owned()),
            ("iteration".to_owned(), self.iteration.to_string()),
            ("views".to_owned(), self.views.to_string()),
            ("downscale".to_owned(), self.downscale.to_string()),
            ("sh_degree".to_owned(), p.sh_degree.to_string()),
            ("gaussians".to_owned(), p.len().to_string()),
            ("rng".to_owned(), self.rng.to_string()),
            ("order_rng".to_owned(), self.order_rng.to_string()),
            ("order_stack".to_owned(), stack.join(",")),
        ]);
        if let Some(origin) = self.adam_origin {
            meta.insert("adam_origin".to_owned(), origin.to_string());
        }
        meta.extend(coc_meta.into_iter().map(|(k, v)| (k.to_owned(), v)));
        let tmp = dir.join(format!(".{CHECKPOINT_FILE}.tmp"));
        safetensors::serialize_to_file(views, Some(meta), &tmp).map_err(|e| {
            CheckpointError::Io {
                path: tmp.clone(),
                source: std::io::Error::other(e),
            }
        })?;
        std::fs::rename(&tmp, &path).map_err(io)?;
        Ok(path)
    }

    /// Reads a checkpoint from `path`: a checkpoint directory, a train output holding
    /// `checkpoint/`, or the state file itself.
    pub fn load(path: &Path) -> Result<Self, CheckpointError> {
        let file = locate(path);
        if path.is_dir() && !file.is_file() {
            return Err(CheckpointError::Format {
                path: path.to_path_buf(),
                why: format!(
                    "it holds no {CHECKPOINT_FILE} (nor checkpoint/{CHECKPOINT_FILE}): resume from \
                     a train output that kept its checkpoint, an OUTPUT.checkpoint folder, or \
                     the state file itself"
                ),
            });
        }
        let data = std::fs::read(&file).map_err(|source| CheckpointError::Io {
            path: file.clone(),
            source,
        })?;
        Reader::new(&file, &data)?.state()
    }
}

/// `path` itself if it is a file, else the state file in it or in its `checkpoint/`.
fn locate(path: &Path) -> PathBuf {
    if path.is_file() {
        return path.to_path_buf();
    }
    let nested = path.join("checkpoint").join(CHECKPOINT_FILE);
    if nested.is_file() {
        nested
    } else {
        path.join(CHECKPOINT_FILE)
    }
}

struct Reader<'a> {
    path: &'a Path,
    st: SafeTensors<'a>,
    meta: HashMap<String, String>,
}

impl<'a> Reader<'a> {
    fn new(path: &'a Path, data: &'a [u8]) -> Result<Self, CheckpointError> {
        let fail = |why: String| CheckpointError::Format {
            path: path.to_path_buf(),
            why,
        };
        let st = SafeTensors::deserialize(data).map_err(|e| {
            fail(
                cocog_formats::safetensors_layout::explain_layout(data)
                    .unwrap_or_else(|| e.to_string()),
            )
        })?;
        let (_, header) = SafeTensors::read_metadata(data).map_err(|e| fail(e.to_string()))?;
        let meta = header.metadata().clone().unwrap_or_default();
        let r = Self { path, st, meta };
        if r.text("format")? != FORMAT {
            return Err(r.fail("metadata `format` is not cocog.checkpoint".into()));
        }
        let version = r.text("version")?;
        if version != VERSION {
            return Err(r.fail(format!(
                "checkpoint version {version}; this cocog reads version {VERSION}"
            )));
        }
        Ok(r)
    }

    fn fail(&self, why: String) -> CheckpointError {
        CheckpointError::Format {
            path: self.path.to_path_buf(),
            why,
        }
    }

    fn text(&self, key: &str) -> Result<&str, CheckpointError> {
        self.meta
            .get(key)
            .map(String::as_str)
            .ok_or_else(|| self.fail(format!("metadata has no `{key}`")))
    }

    fn number<T: std::str::FromStr>(&self, key: &str) -> Result<T, CheckpointError> {
        let text = self.text(key)?;
        text.parse()
            .map_err(|_| self.fail(format!("metadata `{key}` = {text:?} is not a number")))
    }

    /// Tensor `name` of any length.
    fn vector(&self, name: &str) -> Result<Vec<f32>, CheckpointError> {
        let t = self
            .st
            .tensor(name)
            .map_err(|_| self.fail(format!("tensor `{name}` is missing")))?;
        if t.dtype() != Dtype::F32 || t.data().len() % 4 != 0 {
            return Err(self.fail(format!("tensor `{name}` is not f32")));
        }
        Ok(bytemuck::pod_collect_to_vec(t.data()))
    }

    /// Tensor `name` and Adam's moments for it, all of one length.
    fn with_moments(
        &self,
        name: &str,
        adam: &str,
    ) -> Result<(Vec<f32>, MomentState), CheckpointError> {
        let v = self.vector(name)?;
        let n = v.len();
        let m = self.floats(&format!("adam.{adam}.m"), n, 1)?;
        let s = self.floats(&format!("adam.{adam}.v"), n, 1)?;
        Ok((v, MomentState { m, v: s }))
    }

    /// The lens model, when the metadata says the run was CoCoGaussian.
    fn coc(&self) -> Result<Option<CocCheckpoint>, CheckpointError> {
        let Some(variant) = self.meta.get("coc_variant") else {
            return Ok(None);
        };
        let units = self.meta.get(COC_UNITS_KEY).map(String::as_str);
        if let Some(why) = coc_units_problem(variant, units) {
            return Err(self.fail(why));
        }
        let (mlp, mlp_moments) = self.with_moments("coc.mlp", "coc_mlp")?;
        let (compositor, compositor_moments) =
            self.with_moments("coc.compositor", "coc_compositor")?;
        let focus = match self.meta.get("coc_focus_scale") {
            None => None,
            Some(_) => {
                let (values, moments) = self.with_moments("coc.focus", "coc_focus")?;
                let (apertures, aperture_moments) =
                    self.with_moments("coc.apertures", "coc_apertures")?;
                let scale: f32 = self.number("coc_focus_scale")?;
                if !(scale.is_finite() && scale > 0.0) {
                    return Err(self.fail(format!("metadata `coc_focus_scale` = {scale}")));
                }
                if apertures.len() != values.len() {
                    return Err(self.fail(format!(
                        "{} focus distances but {} apertures",
                        values.len(),
                        apertures.len()
                    )));
                }
                let o = self.floats("coc.origin", 1, 3)?;
                Some(FocusState {
                    values,
                    moments,
                    apertures,
                    aperture_moments,
                    scale,
                    origin: [o[0], o[1], o[2]],
                })
            }
        };
        Ok(Some(CocCheckpoint {
            variant: variant.clone(),
            copies: self.number("coc_copies")?,
            width: self.number("coc_width")?,
            centred: self.text("coc_centred")? == "true",
            modulate_base: self.text("coc_modulate_base")? == "true",
            compositor_channels: self.number("coc_compositor_channels")?,
            starts: match self.meta.contains_key("coc_blur_start") {
                true => Some([
                    self.number("coc_blur_start")?,
                    self.number("coc_composite_start")?,
                ]),
                false => None,
            },
            mlp,
            mlp_moments,
            compositor,
            compositor_moments,
            focus,
        }))
    }

    /// Tensor `name`, which must hold `per` × `rows` floats.
    fn floats(&self, name: &str, rows: usize, per: usize) -> Result<Vec<f32>, CheckpointError> {
        let t = self
            .st
            .tensor(name)
            .map_err(|_| self.fail(format!("tensor `{name}` is missing")))?;
        // `rows` comes from the file's metadata: an absurd count must not overflow.
        let bytes = rows.checked_mul(per).and_then(|v| v.checked_mul(4));
        if t.dtype() != Dtype::F32 || bytes != Some(t.data().len()) {
            return Err(self.fail(format!(
                "tensor `{name}` should be {} f32 values ({rows} Gaussians × {per}), found {:?} of {} bytes",
                rows as u128 * per as u128,
                t.dtype(),
                t.data().len()
            )));
        }
        Ok(bytemuck::pod_collect_to_vec(t.data()))
    }

    fn state(&self) -> Result<TrainState, CheckpointError> {
        let n: usize = self.number("gaussians")?;
        let sh_degree: u32 = self.number("sh_degree")?;
        if sh_degree > cocog_engine::MAX_SH_DEGREE {
            return Err(self.fail(format!("metadata `sh_degree` = {sh_degree} is above 3")));
        }
        let sh = 3 * cocog_engine::sh_coeffs_per_channel(sh_degree);
        let triples = |v: Vec<f32>| v.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
        let params = GaussianParams {
            sh_degree,
            means: triples(self.floats("params.means", n, 3)?),
            log_scales: triples(self.floats("params.log_scales", n, 3)?),
            quats: self
                .floats("params.quats", n, 4)?
                .chunks_exact(4)
                .map(|c| [c[0], c[1], c[2], c[3]])
                .collect(),
            opacity_logits: self.floats("params.opacity_logits", n, 1)?,
            sh: self.floats("params.sh", n, sh)?,
        };
        let widths = [3, 3, 4, 1, sh];
        let mut moments: [MomentState; 5] = Default::default();
        for ((name, per), slot) in GROUPS.iter().zip(widths).zip(&mut moments) {
            slot.m = self.floats(&format!("adam.{name}.m"), n, per)?;
            slot.v = self.floats(&format!("adam.{name}.v"), n, per)?;
        }
        let stack = self.text("order_stack")?;
        let order_stack = stack
            .split(',')
            .filter(|s| !s.is_empty())
            .map(|s| s.parse::<u32>())
            .collect::<Result<Vec<_>, _>>()
            .map_err(|_| self.fail(format!("metadata `order_stack` = {stack:?}")))?;
        let iteration: u32 = self.number("iteration")?;
        let adam_origin: Option<u32> = self
            .meta
            .contains_key("adam_origin")
            .then(|| self.number("adam_origin"))
            .transpose()?;
        if let Some(origin) = adam_origin.filter(|&o| o > iteration) {
            return Err(self.fail(format!(
                "metadata `adam_origin` = {origin} is past `iteration` = {iteration}"
            )));
        }
        Ok(TrainState {
            iteration,
            adam_origin,
            views: self.number("views")?,
            downscale: self.number("downscale")?,
            params,
            moments,
            grad_accum: self.floats("stats.grad_accum", n, 1)?,
            grad_denom: self.floats("stats.grad_denom", n, 1)?,
            rng: self.number("rng")?,
            order_rng: self.number("order_rng")?,
            order_stack,
            coc: self.coc()?,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn state() -> TrainState {
        let n = 3;
        let sh = 12;
        let seq = |len: usize, at: f32| (0..len).map(|i| at + i as f32 * 0.5).collect::<Vec<_>>();
        TrainState {
            iteration: 1234,
            adam_origin: Some(1000),
            views: 21,
            downscale: 4,
            params: GaussianParams {
                sh_degree: 1,
                means: vec![[1.0, 2.0, 3.0]; n],
                log_scales: vec![[-4.0, -3.5, -3.0]; n],
                quats: vec![[1.0, 0.0, 0.5, 0.0]; n],
                opacity_logits: seq(n, -1.0),
                sh: seq(n * sh, 0.25),
            },
            moments: std::array::from_fn(|g| {
                let per = [3, 3, 4, 1, sh][g];
                MomentState {
                    m: seq(n * per, g as f32),
                    v: seq(n * per, 10.0 + g as f32),
                }
            }),
            grad_accum: seq(n, 7.0),
            grad_denom: seq(n, 2.0),
            rng: u64::MAX - 5,
            order_rng: 0xDEAD_BEEF_0000_0001,
            order_stack: vec![4, 0, 17],
            coc: None,
        }
    }

    fn lens_model() -> CocCheckpoint {
        let moments = |len: usize, at: f32| MomentState {
            m: (0..len).map(|i| at + i as f32).collect(),
            v: (0..len).map(|i| at + 0.5 * i as f32).collect(),
        };
        CocCheckpoint {
            variant: "paper".into(),
            copies: 5,
            width: 64,
            centred: true,
            modulate_base: false,
            compositor_channels: 8,
            starts: Some([200, 600]),
            mlp: vec![0.25; 7],
            mlp_moments: moments(7, 1.0),
            compositor: vec![-0.5; 4],
            compositor_moments: moments(4, 2.0),
            focus: Some(FocusState {
                values: vec![0.4, 0.6, 0.8],
                moments: moments(3, 3.0),
                apertures: vec![0.01, 0.02, 0.03],
                aperture_moments: moments(3, 4.0),
                scale: 2.5,
                origin: [0.5, -1.0, 2.0],
            }),
        }
    }

    #[test]
    fn a_lens_model_round_trips_with_and_without_focus() {
        let dir = tempfile::tempdir().unwrap();
        let mut s = state();
        s.coc = Some(lens_model());
        s.save(dir.path()).unwrap();
        assert_eq!(TrainState::load(dir.path()).unwrap(), s);
        // Before the blurred phase there are no focus distances yet.
        if let Some(c) = s.coc.as_mut() {
            c.focus = None;
        }
        s.save(dir.path()).unwrap();
        assert_eq!(TrainState::load(dir.path()).unwrap(), s);
    }

    #[test]
    fn a_saved_state_loads_back_identically_from_any_of_its_paths() {
        let dir = tempfile::tempdir().unwrap();
        let ckpt = dir.path().join("checkpoint");
        let s = state();
        let file = s.save(&ckpt).unwrap();
        assert_eq!(TrainState::load(&file).unwrap(), s);
        assert_eq!(TrainState::load(&ckpt).unwrap(), s);
        assert_eq!(TrainState::load(dir.path()).unwrap(), s);
    }

    #[test]
    fn a_wrong_file_is_named_with_what_is_wrong() {
        let dir = tempfile::tempdir().unwrap();
        let missing = TrainState::load(dir.path()).unwrap_err().to_string();
        assert!(
            missing.contains(CHECKPOINT_FILE) && missing.contains("a train output"),
            "{missing}"
        );
        let file = dir.path().join(CHECKPOINT_FILE);
        std::fs::write(&file, b"not safetensors").unwrap();
        let bad = TrainState::load(&file).unwrap_err().to_string();
        assert!(bad.contains("not a cocog checkpoint"), "{bad}");
        // An interrupted copy: the safetensors crate alone says "incomplete metadata".
        let whole = state().save(dir.path()).unwrap();
        let data = std::fs::read(&whole).unwrap();
        std::fs::write(&whole, &data[..data.len() - 10]).unwrap();
        let cut = TrainState::load(&whole).unwrap_err().to_string();
        assert!(cut.contains("truncated"), "{cut}");
        // A valid file whose SH tensor disagrees with the Gaussian count.
        let mut s = state();
        s.params.sh.pop();
        s.save(dir.path()).unwrap();
        let short = TrainState::load(&file).unwrap_err().to_string();
        assert!(short.contains("params.sh"), "{short}");
        // An optimizer rebuilt after the checkpoint's own iteration cannot be.
        let mut s = state();
        s.adam_origin = Some(s.iteration + 1);
        s.save(dir.path()).unwrap();
        let late = TrainState::load(&file).unwrap_err().to_string();
        assert!(late.contains("adam_origin"), "{late}");
        // Older checkpoints have no origin at all, and read as such.
        s.adam_origin = None;
        s.save(dir.path()).unwrap();
        assert_eq!(TrainState::load(&file).unwrap().adam_origin, None);
    }

    #[test]
    fn a_code_variant_checkpoint_without_its_units_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let mut s = state();
        let mut coc = lens_model();
        coc.variant = "code".into();
        s.coc = Some(coc);
        let file = s.save(dir.path()).unwrap();
        assert_eq!(TrainState::load(&file).unwrap(), s);
        // The same file as a build before the mark wrote it.
        let data = std::fs::read(&file).unwrap();
        let st = SafeTensors::deserialize(&data).unwrap();
        let (_, header) = SafeTensors::read_metadata(&data).unwrap();
        let mut meta = header.metadata().clone().unwrap();
        meta.remove(COC_UNITS_KEY);
        safetensors::serialize_to_file(st.tensors(), Some(meta), &file).unwrap();
        let e = TrainState::load(&file).unwrap_err().to_string();
        assert!(
            e.contains(COC_UNITS_KEY) && e.contains("train it again"),
            "{e}"
        );
    }
}
