//! The command line, as clap sees it. Every stage subcommand maps onto a stage name and a
//! JSON options object; options left out are filled by the stage's own defaults.

use std::path::PathBuf;

use clap::{Args, Parser, Subcommand, ValueEnum};

#[derive(Parser)]
#[command(
    name = "cocog",
    version,
    about = "Sharp 3D Gaussian Splatting scenes from photos with depth-of-field blur (CoCoGaussian)",
    long_about = "cocog turns photographs with depth-of-field blur into sharp 3D Gaussian Splatting \
scenes. Each stage reads a scene directory and writes a new one, so stages chain in shell scripts:\n\n  \
cocog ingest llff data/table -o s1\n  cocog densify s1 -o s2\n  cocog train s2 -o s3\n  \
cocog export s3 --format ply -o table.ply\n\n\
Results go to stdout (the output path, or JSON with --json); logs and progress go to stderr. \
Outputs are written beside their target and renamed into place, so a failed run leaves nothing \
half-written. Exit codes: 0 success, 1 failure, 2 usage error, 3 stage not available, 130 cancelled.",
    after_help = "Run `cocog demo` for a complete example, and `cocog plugins` to list every stage."
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
    #[command(flatten)]
    pub global: Global,
}

#[derive(Args)]
pub struct Global {
    /// Directory (or library file) to load plugins from; repeatable. Also read from
    /// COCOG_PLUGIN_PATH (a path list).
    #[arg(long = "plugin-path", global = true, value_name = "DIR")]
    pub plugin_path: Vec<PathBuf>,
    /// Run STAGE from PLUGIN instead of the built-in: a plugin name or a library path;
    /// repeatable, e.g. --use train=./libmy_trainer.so
    #[arg(long = "use", global = true, value_name = "STAGE=PLUGIN")]
    pub use_plugin: Vec<String>,
    /// GPU to use: any adapter whose name contains this text, e.g. "NVIDIA" or "llvmpipe".
    /// Default: the most capable one (discrete > integrated > software). Same as COCOG_ADAPTER.
    #[arg(long, global = true, value_name = "NAME")]
    pub adapter: Option<String>,
    /// Replace the output if it already exists.
    #[arg(long, global = true)]
    pub force: bool,
    /// Make a scene output self-contained: its photos (and depth maps) are hard-linked or
    /// copied into it (images/, depth/) instead of referenced where they are. Model files
    /// (points, Gaussians, lens model) are always carried along.
    #[arg(long = "copy-images", global = true)]
    pub copy_images: bool,
    /// Print the stage's result as JSON on stdout instead of the output path (its `output`
    /// field names the path).
    #[arg(long, global = true)]
    pub json: bool,
    /// Only warnings and errors on stderr, no progress bars.
    #[arg(short, long, global = true, conflicts_with = "verbose")]
    pub quiet: bool,
    /// Debug logs on stderr.
    #[arg(short, long, global = true)]
    pub verbose: bool,
    /// When stderr is not a terminal (a log file, CI), print a progress line for a running
    /// task every SECONDS; 0 turns them off. On a terminal, progress bars show instead.
    #[arg(
        long = "progress-every",
        global = true,
        value_name = "SECONDS",
        default_value_t = 10.0,
        value_parser = seconds
    )]
    pub progress_every: f64,
}

#[derive(Subcommand)]
// Parsed once per process: the size of the largest variant costs nothing.
#[allow(clippy::large_enum_variant)]
pub enum Command {
    /// Read a dataset (COLMAP, NeRF-LLFF or transforms.json) into a new scene directory.
    Ingest(IngestArgs),
    /// Add extra points in the scene's bounding box, coloured from their nearest neighbours.
    Densify(DensifyArgs),
    /// Train Gaussians: CoCoGaussian on defocused photos, or plain 3DGS.
    Train(TrainArgs),
    /// Remove Gaussians whose depth-weighted opacity is too low.
    Prune(PruneArgs),
    /// Write the trained Gaussians to a file other tools open (PLY, glTF, SPZ).
    Export(ExportArgs),
    /// Render a trained scene's views to PNG, optionally with depth (EXR): sharp, or refocused
    /// through a CoCoGaussian scene's lens model.
    Render(RenderArgs),
    /// Score images: PSNR, SSIM (both conventions), LPIPS.
    Eval(EvalArgs),
    /// Write a scene as a COLMAP text model or a transforms.json dataset.
    Convert(ConvertArgs),
    /// Run any stage by name, e.g. one provided by a plugin.
    Stage(StageArgs),
    /// Run a chain of stages described by a pipeline file.
    Run(RunArgs),
    /// List every stage, who provides it, from which file and ABI version.
    Plugins,
    /// Run the main job end to end on a small scene that ships with cocog: a synthetic
    /// defocus dataset trained with plain 3DGS and with CoCoGaussian, scored on sharp
    /// held-out views, with the learned lens of every photo and a focus pull. About ten
    /// minutes on a 2-core CPU without a GPU.
    Demo(DemoArgs),
    /// Measure training speed on this machine: it/s, ms per iteration split into forward /
    /// backward / optimizer / density control, Gaussian count, peak GPU and host memory, and
    /// the engine's operations per step. On a scene (`cocog bench SCENE`), or without one on
    /// random Gaussians (`cocog bench --synthetic 1000000 --size 1920x1080`).
    Bench(BenchArgs),
    /// The lens learned for every training photo (focus distance, aperture), beside the true
    /// one when the dataset records it
    Lens(LensArgs),
}

#[derive(Args)]
pub struct LensArgs {
    /// A scene trained with --method cocog.
    pub scene: PathBuf,
    /// A transforms.json with per-frame `focus_distance_m` (and `aperture_radius_m`) to
    /// compare with. Default: the one beside the photos' folder, when there is one. Its
    /// poses give the scene unit in metres (camera centre distances), so the learned values
    /// are compared in metres whatever the scene's units.
    #[arg(long)]
    pub truth: Option<PathBuf>,
}

#[derive(Clone, Copy, ValueEnum)]
pub enum DatasetFormat {
    /// A COLMAP sparse model (sparse/N/{cameras,images,points3D}.{bin,txt}) and images/.
    Colmap,
    /// NeRF-LLFF poses_bounds.npy with images/ (and images_N/), e.g. Deblur-NeRF data.
    Llff,
    /// A transforms.json dataset (NeRF-synthetic or nerfstudio).
    Nerf,
    /// A folder of photos (or a dataset with images/): runs COLMAP to pose them.
    Photos,
}

#[derive(Args)]
#[command(
    after_help = "Photos: `cocog ingest photos DIR -o SCENE` runs COLMAP (feature \
extraction, matching, mapping, undistortion when the lens needs it) in SCENE/colmap/, keeping its \
log there. Install COLMAP first (Debian/Ubuntu: apt install colmap). Photos that do not register \
are listed with COLMAP's reason. Defocused photos: domain-size pooling is on by default."
)]
pub struct IngestArgs {
    #[arg(value_enum)]
    pub format: DatasetFormat,
    /// The dataset directory (photos: a folder of png/jpg, or a dataset holding images/).
    pub dataset: PathBuf,
    /// The scene directory to create.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Use images downscaled by N (LLFF images_N/ when present, else resampled). Default 1.
    #[arg(long)]
    pub downscale: Option<u32>,
    /// Test split: every N-th view after sorting names; 0 = no test views (every view trains).
    /// Default: the dataset's split (transforms.json), else its hold=N marker, else 8.
    #[arg(long)]
    pub hold: Option<u32>,
    /// COLMAP: which sparse/N model to use. Default: the one with most images.
    #[arg(long)]
    pub model: Option<u32>,
    /// Accept image paths that lead outside the dataset folder (`../`, absolute paths).
    /// Refused by default: a dataset file should not point cocog at other files.
    #[arg(long = "allow-outside")]
    pub allow_outside: bool,
    #[command(flatten)]
    pub photos: PhotosArgs,
}

/// Options of `cocog ingest photos` only.
#[derive(Args)]
pub struct PhotosArgs {
    /// photos: the COLMAP program. Default: `colmap` on PATH.
    #[arg(long)]
    pub colmap: Option<PathBuf>,
    /// photos: auto (exhaustive up to 300 photos, else vocab-tree with --vocab-tree, else
    /// sequential), exhaustive, sequential (photos in capture order) or vocab-tree.
    #[arg(long)]
    pub matcher: Option<String>,
    /// photos: COLMAP vocabulary tree file, for --matcher vocab-tree.
    #[arg(long = "vocab-tree")]
    pub vocab_tree: Option<PathBuf>,
    /// photos: camera model COLMAP fits: SIMPLE_PINHOLE, PINHOLE, SIMPLE_RADIAL (default),
    /// RADIAL, OPENCV. Distorted cameras are undistorted to pinholes afterwards.
    #[arg(long = "camera-model")]
    pub camera_model: Option<String>,
    /// photos: one camera per photo (zoom lenses, mixed cameras) instead of one shared camera.
    #[arg(long = "camera-per-image")]
    pub camera_per_image: bool,
    /// photos: at most this many SIFT features per photo.
    #[arg(long = "max-features")]
    pub max_features: Option<i64>,
    /// photos: turn off domain-size pooling (on by default: it helps with defocus blur, but
    /// forces COLMAP's CPU SIFT).
    #[arg(long = "no-dsp")]
    pub no_dsp: bool,
    /// photos: Lowe's ratio for SIFT matches (higher = looser).
    #[arg(long = "max-ratio", value_parser = finite)]
    pub max_ratio: Option<f64>,
    /// photos: re-match each image pair guided by its two-view geometry.
    #[arg(long = "guided-matching")]
    pub guided_matching: bool,
    /// photos: COLMAP's own triangulation angles (16° initial pair), for captures that
    /// orbit the scene; the default suits forward-facing captures (2°).
    #[arg(long = "orbit")]
    pub orbit: bool,
    /// photos: let COLMAP's mapper refine the focal length from the first image pair on (its
    /// own behaviour). By default it is held at the prior (EXIF, else 1.2 × the longer side)
    /// until every photo is in, then refined with the distortion in one bundle adjustment: far
    /// more reliable on narrow, defocused captures; if that registers too few photos, the free
    /// mapping is tried as well.
    #[arg(long = "free-intrinsics")]
    pub free_intrinsics: bool,
    /// photos: the focal length prior for photos without EXIF, as a multiple of the longer side.
    /// Default COLMAP's 1.2 (about a 43 mm lens on full frame); a phone's main camera is about
    /// 0.8, a 50 mm lens on full frame 1.39. The mapper holds the focal length at its prior
    /// until the final bundle adjustment, so a prior far off costs accuracy (BENCHMARKS.md).
    #[arg(long = "focal-factor", value_name = "F", value_parser = finite)]
    pub focal_factor: Option<f64>,
    /// photos: let COLMAP use GPU SIFT (a CUDA build of COLMAP).
    #[arg(long = "colmap-gpu")]
    pub colmap_gpu: bool,
    /// photos: fail unless this many photos register. Default: half of them, at least 3.
    #[arg(long = "min-registered")]
    pub min_registered: Option<u32>,
}

#[derive(Args)]
pub struct SceneToImages {
    /// The trained scene directory.
    pub scene: PathBuf,
    /// The folder of images to create (with --focus-sweep also a .gif or .mp4 file).
    #[arg(short, long)]
    pub output: PathBuf,
}

#[derive(Args)]
pub struct SceneToScene {
    /// The input scene directory.
    pub scene: PathBuf,
    /// The scene directory to create.
    #[arg(short, long)]
    pub output: PathBuf,
}

#[derive(Args)]
pub struct DensifyArgs {
    #[command(flatten)]
    pub io: SceneToScene,
    /// How many candidate points to draw (Deblurring-3DGS uses about 200k). Default 200000.
    #[arg(long)]
    pub points: Option<u64>,
    /// Random seed for the candidate points. Default 0.
    #[arg(long)]
    pub seed: Option<u64>,
    /// Drop candidates with no input point within this distance (scene units). Default 2.0,
    /// the reference code's, read in the scene's own units.
    #[arg(long = "max-distance", value_parser = finite)]
    pub max_distance: Option<f64>,
}

#[derive(Args)]
pub struct PruneArgs {
    #[command(flatten)]
    pub io: SceneToScene,
    /// Depth-weighted opacity below which a Gaussian is removed. Default 0.005.
    #[arg(long, value_parser = finite)]
    pub threshold: Option<f64>,
    /// Depth range factor of the weighting (Deblurring-3DGS): the threshold is divided by up
    /// to this at the farthest z. Default 3.
    #[arg(long, value_parser = finite)]
    pub range: Option<f64>,
}

#[derive(Clone, Copy, ValueEnum)]
pub enum Method {
    /// CoCoGaussian: circle-of-confusion Gaussians, for photos with depth-of-field blur.
    /// Learns per-photo focus distances and writes a lens model that `cocog render
    /// --focus-distance` refocuses with; on the blurred dev scenes its sharp base beats 3dgs
    /// by about 5 dB at 100×75 (BENCHMARKS.md), at about 2.8× the cost of a step.
    Cocog,
    /// Plain 3D Gaussian Splatting, for sharp photos.
    #[value(name = "3dgs")]
    Gs3d,
}

#[derive(Args)]
#[command(
    after_help = "While training runs, OUTPUT.train-log.jsonl grows by one JSON line per \
reading (follow it with `tail -f`): `start`, then the training view's loss and PSNR every 100 \
iterations (every tenth of a short run), `eval` records with --eval-every, and a closing \
`summary`. When training succeeds it becomes OUTPUT/train-log.jsonl; when it is interrupted it \
stays beside OUTPUT.checkpoint and --resume continues both."
)]
pub struct TrainArgs {
    #[command(flatten)]
    pub io: SceneToScene,
    /// Training method. Default cocog; a resumed run keeps its checkpoint's. 3dgs is the
    /// cheaper step for photos without depth-of-field blur.
    #[arg(long, value_enum)]
    pub method: Option<Method>,
    /// Training iterations, one view each. Default 7000 (3DGS's and the paper's long runs
    /// use 30000).
    #[arg(long)]
    pub iterations: Option<u64>,
    /// cocog: CoC Gaussians per base Gaussian, M. Default: the variant's (code 4, paper 5).
    #[arg(long = "coc-gaussians")]
    pub coc_gaussians: Option<u64>,
    /// cocog: `paper` (aperture K, scaling β, directions from h_θ; h_θ from 2000 with the
    /// renders averaged, F from 6000), `lens` (a thin lens per photo: the CoC radius follows
    /// that photo's learned aperture and focus distance, h_θ shapes the copies inside it;
    /// copies centred on their base, heads started at 0.01, h_θ from 1000, F from 6000) or
    /// `code` (the released code: free offsets gated by |1/d - 1/d_F| in the scene's units,
    /// h_θ and F from 1500). Default paper: at 7000 iterations on the dev scenes it leads
    /// lens on mean PSNR, LPIPS and focus error; code stays under plain 3DGS there: on scenes
    /// in metres its heads' released initial scale starts the copies far wider than the blur
    /// (with `--coc-head-init 0.1` dev-table's base gained 1.2 dB over its first 200 blurred
    /// steps instead of losing 2.7; BENCHMARKS.md). Runs shorter than 7000
    /// iterations start h_θ and F at the same shares of the run. A resumed run keeps its
    /// checkpoint's variant.
    #[arg(long = "coc-variant")]
    pub coc_variant: Option<String>,
    /// cocog: first iteration rendered through the CoC Gaussians (plain 3DGS before).
    /// Default: the variant's (paper 2000, lens 1000, code 1500), at the same share of a run
    /// shorter than 7000 iterations; a resumed run keeps its own.
    #[arg(long = "blur-start")]
    pub blur_start: Option<u64>,
    /// cocog: first iteration composited by the CNN F (the renders are averaged before).
    /// Default: the variant's (6000; code 1500), fitted like --blur-start; given alone, the
    /// other start stays the variant's unfitted one.
    #[arg(long = "composite-start")]
    pub composite_start: Option<u64>,
    /// cocog: hidden channels of F. Default 64 (as published); 8–16 train far faster on a CPU.
    #[arg(long = "compositor-channels")]
    pub compositor_channels: Option<u64>,
    /// cocog: subtract the copies' mean offset, so the CoC Gaussians sit around their base as
    /// a circle of confusion sits around its in-focus point. Default: on for lens, off for
    /// code and paper; `--coc-centred=false` turns it off.
    #[arg(long = "coc-centred", num_args = 0..=1, require_equals = true,
          default_missing_value = "true", value_name = "BOOL")]
    pub coc_centred: Option<bool>,
    /// cocog: leave the base set's scale and rotation unmodulated while training, so training
    /// renders the base as the test views do (the released code modulates it).
    #[arg(long = "coc-sharp-base")]
    pub coc_sharp_base: bool,
    /// cocog: scale of h_θ's initial head weights (1 = PyTorch's default; smaller starts the
    /// CoC Gaussians near their base instead of scattered). Default: 0.01 for lens, 1 for code
    /// and paper.
    #[arg(long = "coc-head-init", value_parser = finite)]
    pub coc_head_init: Option<f64>,
    /// cocog: initial learning rate of h_θ, F and the focus distances at the blur start,
    /// decaying exponentially at 100× per run length (27× by the end of a 7000-iteration run
    /// from 2000). Default 1e-3 (both sources); short runs learn the lens faster with more.
    #[arg(long = "kernel-lr", value_parser = finite)]
    pub kernel_lr: Option<f64>,
    /// cocog: where each photo's focus distance starts. `mean`: the mean distance from the
    /// camera to the Gaussians, as both sources (default); `estimate`: depth from defocus at
    /// the blur start, fitting each photo with the warm-up render blurred by a thin lens; or a
    /// transforms.json whose frames carry `focus_distance_m` in scene units (the cocog bench
    /// and demo datasets have it).
    #[arg(long = "focus-init", value_name = "mean|estimate|TRANSFORMS_JSON")]
    pub focus_init: Option<String>,
    /// cocog, experimental: every N iterations after the blur start, estimate each photo's
    /// focus again by depth from defocus against the current base Gaussians and replace the
    /// learned one (the gradient alone moves a focus little from a wrong start). On a
    /// two-plane test scene half the runs found both planes and half locked every photo onto
    /// one (BENCHMARKS.md). Default 0 (never).
    #[arg(long = "refocus-every", value_name = "N")]
    pub refocus_every: Option<u64>,
    /// cocog: the last iteration --refocus-every applies to. Default: the end of the run.
    #[arg(long = "refocus-until", value_name = "IT")]
    pub refocus_until: Option<u64>,
    /// Train on images downscaled by N (intrinsics scaled to match). Default 1.
    #[arg(long)]
    pub downscale: Option<u32>,
    /// Random seed (view order, splits, random backgrounds). Default 0.
    #[arg(long)]
    pub seed: Option<u64>,
    /// Largest spherical-harmonics degree, 0 to 3. Default 3.
    #[arg(long = "sh-degree")]
    pub sh_degree: Option<u64>,
    /// What photos with an alpha channel are composited over, and what the Gaussians render
    /// over: black, white or R,G,B in 0..1 (e.g. white for NeRF-synthetic's RGBA renders).
    /// Render and eval use it too (it is recorded in scene.json). Default black.
    #[arg(long)]
    pub background: Option<String>,
    /// Composite each training render over a random colour, which keeps floaters from
    /// hiding behind a matching background.
    #[arg(long = "random-background")]
    pub random_background: bool,
    /// Continue an earlier run: a train output (uses its checkpoint/) or the OUTPUT.checkpoint
    /// folder an interrupted run left. Give the same --downscale; --iterations is the total.
    #[arg(long)]
    pub resume: Option<PathBuf>,
    /// Save OUTPUT.checkpoint every N iterations while training (0: only on Ctrl-C).
    /// Default 1000.
    #[arg(long = "checkpoint-every")]
    pub checkpoint_every: Option<u64>,
    /// Score the test views (PSNR, SSIM) every N iterations and at the end, into the log
    /// (`eval` records) and onto stderr. Default 0: never.
    #[arg(long = "eval-every")]
    pub eval_every: Option<u64>,
    #[command(flatten)]
    pub schedule: ScheduleArgs,
}

#[derive(Clone, Copy, ValueEnum)]
pub enum SchedulePreset {
    /// INRIA's rules without the large-Gaussian prune, which on forward-facing captures
    /// deletes the background after the first opacity reset (measured: BENCHMARKS.md); the
    /// default of --method 3dgs.
    Auto,
    /// CoCoGaussian's released code (Deblurring 3DGS's density control): densify until
    /// 20000, no opacity reset, depth-weighted pruning (range 3), the point addition at 2500,
    /// D-SSIM weight 0.25, position learning rate 3.2e-4; the default of --method cocog.
    Deblur,
    /// INRIA 3DGS (2023) exactly, for comparison.
    Inria,
}

/// Density control and its schedule. Each flag overrides one constant of the preset; the
/// full schedule a run used, scene scale included, is in the output's scene.json history.
#[derive(Args)]
#[command(next_help_heading = "Density schedule")]
pub struct ScheduleArgs {
    /// Preset for every constant below. Default: deblur for --method cocog, auto for 3dgs.
    #[arg(long, value_enum)]
    pub schedule: Option<SchedulePreset>,
    /// What the position learning rate and the world-space rules (clone/split boundary,
    /// large-Gaussian prune) scale with: `extent` (INRIA: 1.1 × the largest camera distance
    /// from their mean), `depth` (the larger of that and the points' median distance from the
    /// cameras), or a length in scene units. Default extent.
    #[arg(long = "scene-scale")]
    pub scene_scale: Option<String>,
    /// Densify after this iteration. Default 500.
    #[arg(long = "densify-from")]
    pub densify_from: Option<u64>,
    /// Densify (and reset opacities) only before this iteration. Default 20000 (deblur, the
    /// cocog default), 15000 (auto, inria).
    #[arg(long = "densify-until")]
    pub densify_until: Option<u64>,
    /// Iterations between densifications. Default 100.
    #[arg(long = "densify-every")]
    pub densify_every: Option<u64>,
    /// Mean view-space gradient at which a Gaussian is cloned (small) or split (large).
    /// Default 0.0002.
    #[arg(long = "densify-grad", value_parser = finite)]
    pub densify_grad: Option<f64>,
    /// Largest scale, × scene scale, of a Gaussian that is cloned rather than split.
    /// Default 0.01.
    #[arg(long = "percent-dense", value_parser = finite)]
    pub percent_dense: Option<f64>,
    /// Prune Gaussians below this opacity when densifying. Default 0.005.
    #[arg(long = "prune-opacity", value_parser = finite)]
    pub prune_opacity: Option<f64>,
    /// Prune Gaussians larger than this × scene scale, from the first opacity reset on
    /// (from the first densification when resets are off); 0 turns it off. Default 0 (deblur,
    /// auto), 0.1 (inria): on a capture around an object 0.1 removes large floaters.
    #[arg(long = "prune-large", value_parser = finite)]
    pub prune_large: Option<f64>,
    /// Clamp every opacity to 0.01 each N iterations while densifying; 0 never.
    /// Default 0 (deblur, the cocog default), 3000 (auto, inria).
    #[arg(long = "opacity-reset-every")]
    pub opacity_reset_every: Option<u64>,
    /// Raise the spherical-harmonics degree every N iterations. Default 1000.
    #[arg(long = "sh-every")]
    pub sh_every: Option<u64>,
    /// Divide the prune threshold by up to this for the farthest Gaussians (depth along the
    /// cameras' mean viewing direction); 1 prunes uniformly. Default 1 (auto, inria), 3 (deblur).
    #[arg(long = "depth-prune-range", value_parser = finite)]
    pub depth_prune_range: Option<f64>,
    /// Weight of D-SSIM in the loss. Default 0.2 (auto, inria), 0.25 (deblur).
    #[arg(long = "lambda-dssim", value_parser = finite)]
    pub lambda_dssim: Option<f64>,
    /// Initial position learning rate × scene scale, decayed 100× over the run. Default 1.6e-4
    /// (auto, inria), 3.2e-4 (deblur).
    #[arg(long = "position-lr", value_parser = finite)]
    pub position_lr: Option<f64>,
    /// Deblurring 3DGS's point addition at this iteration (CoCoGaussian's released code:
    /// 2500): candidates drawn in the Gaussians' box take the colour of their 4 nearest, then
    /// every Gaussian restarts with a neighbour-sized round shape and opacity 0.1; 0 never.
    /// Default 2500 (deblur), 0 (auto, inria).
    #[arg(long = "add-points-at")]
    pub add_points_at: Option<u32>,
    /// Most points the addition draws; it draws min(this, the initial cloud's box volume /
    /// 1.1³) and drops those with no Gaussian within --add-points-distance. Default 200000.
    #[arg(long = "add-points-max")]
    pub add_points_max: Option<u32>,
    /// Drop candidates with no Gaussian this close, in scene units. Default 2.0 in the units
    /// of --add-points-frame.
    #[arg(long = "add-points-distance", value_parser = finite)]
    pub add_points_distance: Option<f64>,
    /// The units the addition's volume rule and distance are read in: `colmap`, the frame
    /// COLMAP's mapper leaves a reconstruction in (camera centres' robust box 10 across), where
    /// the released code's data live and it adds about 200k points; or `scene`, this scene's
    /// own units (in metres it adds a handful). Default scene.
    #[arg(long = "add-points-frame", value_parser = ["colmap", "scene"])]
    pub add_points_frame: Option<String>,
}

/// A duration in seconds: finite and not negative.
fn seconds(s: &str) -> Result<f64, String> {
    let v = finite(s)?;
    if v >= 0.0 {
        Ok(v)
    } else {
        Err(format!("{s} is negative"))
    }
}

/// A number that is not NaN or infinite (JSON cannot carry those, and they mean nothing here).
fn finite(s: &str) -> Result<f64, String> {
    let v: f64 = s.parse().map_err(|e| format!("{e}"))?;
    if v.is_finite() {
        Ok(v)
    } else {
        Err(format!("{s} is not a finite number"))
    }
}

#[derive(Clone, Copy, ValueEnum)]
pub enum ExportFormat {
    /// INRIA 3DGS PLY: opens in SuperSplat, Spark, Brush, three.js, Babylon.js.
    Ply,
    /// glTF binary with KHR_gaussian_splatting (three.js, Babylon.js).
    Glb,
    /// Niantic SPZ (version 3, gzip; at SH 3, 65 bytes a Gaussian before gzip against the PLY's
    /// 248): SuperSplat, Spark, Babylon.js, three.js. Stored in SPZ's RUB axes (turned 180°
    /// about X from the PLY's, as Niantic's library converts PLY); positions to 2^-12 scene
    /// units within ±2048.
    Spz,
}

#[derive(Args)]
pub struct ExportArgs {
    /// A trained scene (its gaussians.ply).
    pub scene: PathBuf,
    #[arg(long, value_enum)]
    pub format: ExportFormat,
    /// The file to write.
    #[arg(short, long)]
    pub output: PathBuf,
}

#[derive(Args)]
#[command(
    after_help = "Refocusing (scenes trained with --method cocog): the learned lens \
model renders any view with a chosen depth of field. Focus distances are in scene units \
(metres where the poses are metric), measured from the camera centre; --aperture multiplies \
the learned aperture of the training photos (1 = as photographed, 0 = exactly the sharp \
render, 2 = twice the blur). Examples:
  cocog render t -o r --split train --as-photographed    each photo's own learned lens
  cocog render t -o r --focus-distance 0.8 --aperture 1.5
  cocog render t -o r --focus-distance from:003.png      the focus of training photo 003
  cocog render t -o r --focus-at 200,150                 focus on what pixel (200,150) sees
  cocog render t --views 000 --focus-sweep 0.5:3:24 -o pull.gif   a focus pull"
)]
pub struct RenderArgs {
    #[command(flatten)]
    pub io: SceneToImages,
    /// Which views: test, train or all. Default test.
    #[arg(long)]
    pub split: Option<String>,
    /// Render at the views' size divided by N (use the training --downscale to compare).
    /// Default 1.
    #[arg(long)]
    pub downscale: Option<u32>,
    /// Background colour: black, white or R,G,B in 0..1. Default: the one the scene was
    /// trained over (train --background).
    #[arg(long)]
    pub background: Option<String>,
    /// Only these views: comma-separated names, render names or stems (e.g. 000,008); a stem
    /// two views share (NeRF-synthetic's r_0) is refused: give test_r_0. --view NAME for one.
    /// Default: the split.
    #[arg(long, visible_alias = "view")]
    pub views: Option<String>,
    /// New cameras instead of the scene's views, from a JSON file in scene.json's convention:
    /// {"world_from_camera": [[4 numbers] × 4] (OpenCV axes: x right, y down, z forward),
    /// "camera": a scene camera id for the intrinsics (default: the first training view's),
    /// "name": the output's stem} or a list of them. Works with every refocus option.
    #[arg(long, conflicts_with = "views")]
    pub camera: Option<PathBuf>,
    /// Refocus: the distance in focus from the camera centre, in scene units, or
    /// from:VIEW for a training photo's learned focus distance (and aperture).
    #[arg(long = "focus-distance")]
    pub focus_distance: Option<String>,
    /// Refocus: focus each view on the surface under its pixel X,Y (the render's depth).
    #[arg(long = "focus-at")]
    pub focus_at: Option<String>,
    /// Refocus: every training view through its own learned focus and aperture, i.e. what
    /// the model thinks the photo looked like (views without a learned lens render sharp).
    #[arg(long = "as-photographed")]
    pub as_photographed: bool,
    /// Refocus: multiplies the learned aperture (1 = as photographed, 0 = sharp). Default 1.
    #[arg(long, value_parser = finite)]
    pub aperture: Option<f64>,
    /// Refocus: blend the CoC renders with the learned compositor (learned) or average them
    /// (mean). Default: learned if training reached --composite-start, else mean.
    #[arg(long)]
    pub composite: Option<String>,
    /// A focus pull over one view (--views NAME, or --camera with one camera): NEAR:FAR:FRAMES, focus distances even in
    /// 1/distance (as a lens's focus ring). -o FILE.gif writes an animation, FILE.mp4 needs
    /// ffmpeg on PATH, a folder gets the frames as PNG.
    #[arg(long = "focus-sweep")]
    pub focus_sweep: Option<String>,
    /// Also write depth/<view>.exr: expected depth along the optical axis divided by the
    /// pixel's alpha, 0 where nothing was seen.
    #[arg(long)]
    pub depth: bool,
}

#[derive(Args)]
pub struct EvalArgs {
    /// A trained scene to render and score against its own photos.
    pub scene: Option<PathBuf>,
    /// With SCENE: which views to score: test, train or all. Default test.
    // `pred` conflicts with `scene`, which makes clap waive `requires`: name the clash too.
    #[arg(long, requires = "scene", conflicts_with = "pred")]
    pub split: Option<String>,
    /// With SCENE: render and score at the photos' size divided by N (match the training
    /// --downscale). Default 1.
    #[arg(long, requires = "scene", conflicts_with = "pred")]
    pub downscale: Option<u32>,
    /// A folder of predicted images (instead of a scene).
    #[arg(long, requires = "gt", conflicts_with = "scene")]
    pub pred: Option<PathBuf>,
    /// The folder of ground-truth images, matched to --pred by file stem (a render named
    /// with its folder, test_r_0.png, also matches r_0.png in a folder named test).
    #[arg(long)]
    pub gt: Option<PathBuf>,
    /// Where to write metrics.json. Default: metrics.json inside SCENE; with --pred, no file:
    /// the scores go to stdout (a table, or JSON with --json).
    #[arg(short, long)]
    pub output: Option<PathBuf>,
    /// LPIPS: auto (when weights are installed), require, or off. Install the weights once
    /// with scripts/lpips/fetch-weights.sh. Default auto.
    #[arg(long)]
    pub lpips: Option<String>,
    /// Also compute LPIPS with the VGG-16 backbone (AlexNet is the papers' choice).
    #[arg(long)]
    pub vgg: bool,
    /// Folder holding alex.safetensors / vgg.safetensors (default: COCOG_LPIPS_WEIGHTS,
    /// else the user cache dir).
    #[arg(long = "lpips-weights")]
    pub lpips_weights: Option<PathBuf>,
    /// Worker threads; 0 uses every core. Default 0.
    #[arg(long)]
    pub threads: Option<u64>,
}

#[derive(Clone, Copy, ValueEnum)]
pub enum ConvertTarget {
    /// A COLMAP text model (cameras.txt, images.txt, points3D.txt).
    Colmap,
    /// transforms.json with OpenGL camera-to-world matrices.
    Nerf,
}

#[derive(Args)]
pub struct ConvertArgs {
    /// A scene directory (cameras, poses, points).
    pub scene: PathBuf,
    #[arg(long, value_enum)]
    pub to: ConvertTarget,
    /// The dataset folder to write.
    #[arg(short, long)]
    pub output: PathBuf,
}

#[derive(Args)]
pub struct StageArgs {
    /// The stage name (see `cocog plugins`).
    pub name: String,
    /// The input: a scene directory, or a dataset for ingest stages.
    pub input: PathBuf,
    /// Where the stage writes: a scene directory, or a file for file stages.
    #[arg(short, long)]
    pub output: PathBuf,
    /// A stage option, KEY=VALUE; VALUE is read as JSON when it parses (numbers, true),
    /// else as a string. Repeatable.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub set: Vec<String>,
}

#[derive(Args)]
#[command(after_help = "A pipeline file (paths relative to it):
  [pipeline]
  input = \"data/defocuscozy2room\"
  output = \"scene.ply\"
  stages = [\"ingest-llff\", \"train\", \"prune\", \"export\"]
  [ingest-llff]
  downscale = 4
  [train]
  iterations = 7000
  [export]
  format = \"ply\"
The last stage writes OUTPUT, the others OUTPUT.stages/NN-STAGE. Every stage's option names,
types, ranges and choices are checked before the first stage runs (`cocog plugins --json`
lists them), and so is the order: ingest first; export, render, eval, eval-scene or convert
last; no stage that reads Gaussians (prune, export, render, eval-scene) after an ingest without
a train (or a plugin stage) between, as an ingest's scene has none. Values that depend on the
input (a blur start past the run's end) are checked when their stage starts.")]
pub struct RunArgs {
    /// The pipeline file (TOML): [pipeline] input, output, stages, plus one table of
    /// options per stage.
    pub pipeline: PathBuf,
    /// Continue an interrupted or changed pipeline: stages whose output exists from the same
    /// input with the same options are kept, the first changed one and all after it run
    /// again, and an interrupted training stage continues from its checkpoint.
    #[arg(long)]
    pub resume: bool,
}

#[derive(Args)]
pub struct DemoArgs {
    /// Where to put the demo's dataset and scenes.
    #[arg(short, long, default_value = "cocog-demo")]
    pub output: PathBuf,
    /// The larger version for a GPU: the same photographs at 192×144 and 7000
    /// iterations per method instead of 64×48 and 1200. On a CPU it takes hours.
    #[arg(long)]
    pub full: bool,
    /// Iterations per method (the schedule scales with it: densification from a sixth to
    /// four fifths of the run, cocog's blur from a quarter).
    #[arg(long, value_parser = clap::value_parser!(u32).range(8..))]
    pub iterations: Option<u32>,
}

#[derive(Args)]
#[command(group(clap::ArgGroup::new("workload").required(true).args(["scene", "synthetic"])))]
pub struct BenchArgs {
    /// An ingested scene directory (with points), e.g. from `cocog ingest`.
    pub scene: Option<PathBuf>,
    /// Instead of a scene: N random Gaussians filling a ball, seen by a ring of cameras
    /// (every Gaussian in every frame, unless --zoom), at a fixed count (no density control) with all SH
    /// bands active from the third iteration. Measures speed at any count and size without
    /// photos.
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(1..))]
    pub synthetic: Option<u32>,
    /// --synthetic: the image size, WIDTHxHEIGHT. Default 1920x1080.
    #[arg(long, value_name = "WxH", conflicts_with = "scene", value_parser = parse_size)]
    pub size: Option<(u32, u32)>,
    /// --synthetic: cameras in the ring (the training views). Default 8.
    #[arg(long, conflicts_with = "scene", value_parser = clap::value_parser!(u32).range(1..=1024))]
    pub views: Option<u32>,
    /// --synthetic: seed of the random Gaussians. Default 0.
    #[arg(long, conflicts_with = "scene")]
    pub seed: Option<u64>,
    /// --synthetic: multiply the cameras' focal length by Z (≥ 1), so each frame sees the
    /// middle of the ball and the rest of the Gaussians are culled, as in a capture that
    /// surrounds the viewer (e.g. 3: about a third of them in each frame). Default 1.
    #[arg(long, value_name = "Z", conflicts_with = "scene")]
    pub zoom: Option<f64>,
    /// --synthetic: also write the workload to DIR (gaussians.ply in the INRIA layout and
    /// cameras.json), for a peer rasterizer to time the same Gaussians
    /// (`bench/peer_gsplat.py workload DIR --out FILE`).
    #[arg(long = "write-workload", value_name = "DIR", requires = "synthetic")]
    pub write_workload: Option<PathBuf>,
    /// Train on images downscaled by N. Default 1.
    #[arg(long, default_value_t = 1)]
    pub downscale: u32,
    /// Timed iterations: this many unprofiled (throughput), then as many profiled (split).
    #[arg(long, default_value_t = 100)]
    pub iterations: u32,
    /// Untimed iterations first (shader compilation, first allocations).
    #[arg(long, default_value_t = 10)]
    pub warmup: u32,
    /// Start from a training checkpoint (a train output or OUTPUT.checkpoint) to measure at a
    /// realistic Gaussian count instead of the SfM points.
    #[arg(long)]
    pub resume: Option<PathBuf>,
    /// Largest SH degree. Default 3 (reached only after 3000 iterations, or from --resume).
    #[arg(long = "sh-degree", default_value_t = 3)]
    pub sh_degree: u32,
    /// What to time: a plain 3DGS step, or a CoCoGaussian step (h_θ, M + 1 renders, F) from
    /// the first timed iteration on. Default 3dgs.
    #[arg(long, value_enum, default_value_t = Method::Gs3d)]
    pub method: Method,
    /// cocog: `paper`, `lens` or `code` (see `cocog train --help`). Default paper.
    #[arg(long = "coc-variant", default_value = "paper")]
    pub coc_variant: String,
    /// cocog: CoC Gaussians per base Gaussian, M. Default: the variant's.
    #[arg(long = "coc-gaussians")]
    pub coc_gaussians: Option<u32>,
    /// cocog: hidden channels of F. Default 64.
    #[arg(long = "compositor-channels", default_value_t = 64)]
    pub compositor_channels: u32,
    /// cocog: centred CoC copies (as `train --coc-centred`). Default: the variant's.
    #[arg(long = "coc-centred", num_args = 0..=1, require_equals = true,
          default_missing_value = "true", value_name = "BOOL")]
    pub coc_centred: Option<bool>,
    /// Also time every GPU kernel (timestamp queries) over the profiled iterations.
    #[arg(long)]
    pub kernels: bool,
}

/// `WIDTHxHEIGHT`, both at least 1 and at most 65536.
fn parse_size(s: &str) -> Result<(u32, u32), String> {
    let bad = || format!("expected WIDTHxHEIGHT such as 1920x1080, got '{s}'");
    let (w, h) = s.split_once(['x', 'X', '×']).ok_or_else(bad)?;
    let side = |v: &str| {
        v.trim()
            .parse::<u32>()
            .ok()
            .filter(|v| (1..=65536).contains(v))
    };
    Ok((side(w).ok_or_else(bad)?, side(h).ok_or_else(bad)?))
}
