//! Fuzz targets for cocog's file readers, and the valid files their corpora start from.
//!
//! Every target writes the input where its reader expects a file and calls the public reader;
//! a reader may refuse the input with an error but must never panic, abort or hang. The seeds
//! come from cocog's own writers, so the fuzzer starts from files the readers accept.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use cocog_formats::Splats;
use cocog_formats::colmap::{
    Camera, CameraModel, Image, Model, Point2D, Point3D, TrackElement, write_bin,
};
use cocog_formats::llff::LlffView;
use cocog_formats::ply::PointCloud;
use cocog_pipeline::scene::{Bounds, Camera as SceneCamera, Lens, Scene, Split, View};
use cocog_train::{MomentState, TrainState};

/// Every target, by name: its binary in `fuzz_targets/`, its corpus and regression folders.
pub const TARGETS: [&str; 6] = [
    "colmap_bin",
    "ply",
    "glb",
    "npy",
    "checkpoint",
    "scene_json",
];

/// The COLMAP model files; a `colmap_bin` input is one selector byte, then that file.
pub const COLMAP_FILES: [&str; 3] = ["cameras.bin", "images.bin", "points3D.bin"];

/// A scratch folder for this process, kept until it exits.
fn scratch() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let dir = std::env::temp_dir().join(format!("cocog-fuzz-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("create scratch folder");
        dir
    })
}

/// What a reader made of an input: accepted, or refused with its message. Either is fine for
/// the fuzzer; seeds must be accepted.
pub type Outcome = Result<(), String>;

fn put(name: &str, data: &[u8]) -> PathBuf {
    let path = scratch().join(name);
    std::fs::write(&path, data).expect("write fuzz input");
    path
}

/// `read_model` on a folder of valid COLMAP binary files with one replaced by the input.
pub fn colmap_bin(data: &[u8]) -> Outcome {
    static VALID: OnceLock<[Vec<u8>; 3]> = OnceLock::new();
    let valid = VALID.get_or_init(colmap_files);
    let Some((&which, file)) = data.split_first() else {
        return Err("empty input".into());
    };
    let which = usize::from(which) % 3;
    let dir = scratch().join("colmap");
    std::fs::create_dir_all(&dir).expect("create model folder");
    for (i, name) in COLMAP_FILES.iter().enumerate() {
        let bytes = if i == which { file } else { &valid[i][..] };
        std::fs::write(dir.join(name), bytes).expect("write fuzz input");
    }
    cocog_formats::colmap::read_model(&dir)
        .map(drop)
        .map_err(|e| e.to_string())
}

/// Both PLY readers: plain point clouds and 3DGS splats.
pub fn ply(data: &[u8]) -> Outcome {
    let path = put("input.ply", data);
    let points = cocog_formats::ply::read_points(&path).map(drop);
    let splats = cocog_formats::ply::read_splats(&path).map(drop);
    // A valid file is one of the two kinds; either reader accepting it is success.
    points.or(splats).map_err(|e| e.to_string())
}

/// The glTF binary reader (`KHR_gaussian_splatting`).
pub fn glb(data: &[u8]) -> Outcome {
    let path = put("input.glb", data);
    cocog_formats::glb::read_glb(&path)
        .map(drop)
        .map_err(|e| e.to_string())
}

/// The `.npy` reader: LLFF `poses_bounds.npy`.
pub fn npy(data: &[u8]) -> Outcome {
    let path = put("poses_bounds.npy", data);
    cocog_formats::llff::read_poses_bounds(&path)
        .map(drop)
        .map_err(|e| e.to_string())
}

/// The training checkpoint reader (safetensors).
pub fn checkpoint(data: &[u8]) -> Outcome {
    let path = put(cocog_train::CHECKPOINT_FILE, data);
    TrainState::load(&path).map(drop).map_err(|e| e.to_string())
}

/// `scene.json`: parse, header check and validation.
pub fn scene_json(data: &[u8]) -> Outcome {
    let dir = scratch().join("scene");
    std::fs::create_dir_all(&dir).expect("create scene folder");
    std::fs::write(dir.join(cocog_pipeline::scene::MANIFEST), data).expect("write fuzz input");
    Scene::load(&dir).map(drop).map_err(|e| e.to_string())
}

/// Runs target `name` on `data`; `None` for an unknown name.
pub fn run(name: &str, data: &[u8]) -> Option<Outcome> {
    let f: fn(&[u8]) -> Outcome = match name {
        "colmap_bin" => colmap_bin,
        "ply" => ply,
        "glb" => glb,
        "npy" => npy,
        "checkpoint" => checkpoint,
        "scene_json" => scene_json,
        _ => return None,
    };
    Some(f(data))
}

/// Called once when a fuzz binary starts. With `COCOG_FUZZ_SEEDS=DIR` set, writes target
/// `name`'s seeds into `DIR`, checks that its reader accepts each, and exits instead of fuzzing.
pub fn init(name: &str) {
    let Some(dir) = std::env::var_os("COCOG_FUZZ_SEEDS") else {
        return;
    };
    let dir = PathBuf::from(dir);
    std::fs::create_dir_all(&dir).expect("create corpus folder");
    for (file, data) in seeds(name) {
        // A refused seed would start the corpus on an error path.
        if let Some(Err(e)) = run(name, &data) {
            eprintln!("seed {name}/{file} is refused by its own reader: {e}");
            std::process::exit(1);
        }
        std::fs::write(dir.join(file), data).expect("write seed");
    }
    let _ = std::fs::remove_dir_all(scratch());
    std::process::exit(0);
}

/// Writes with `write` into a scratch file and returns its bytes.
fn written(name: &str, write: impl FnOnce(&Path)) -> Vec<u8> {
    let dir = scratch().join("seeds");
    std::fs::create_dir_all(&dir).expect("create seed folder");
    let path = dir.join(name);
    write(&path);
    std::fs::read(&path).expect("read seed back")
}

fn colmap_model() -> Model {
    Model {
        cameras: vec![
            Camera {
                id: 1,
                model: CameraModel::OpenCv,
                width: 64,
                height: 48,
                params: vec![50.0, 50.0, 32.0, 24.0, 0.01, -0.01, 0.001, 0.001],
            },
            Camera {
                id: 2,
                model: CameraModel::Pinhole,
                width: 32,
                height: 32,
                params: vec![30.0, 30.0, 16.0, 16.0],
            },
        ],
        images: vec![
            Image {
                id: 3,
                qvec: [1.0, 0.0, 0.0, 0.0],
                tvec: [0.0, 0.0, 1.0],
                camera_id: 1,
                name: "a.png".into(),
                points2d: vec![
                    Point2D {
                        xy: [1.0, 2.0],
                        point3d_id: Some(7),
                    },
                    Point2D {
                        xy: [3.0, 4.0],
                        point3d_id: None,
                    },
                ],
            },
            Image {
                id: 4,
                qvec: [0.0, 1.0, 0.0, 0.0],
                tvec: [0.5, 0.0, 1.0],
                camera_id: 2,
                name: "sub/b.png".into(),
                points2d: vec![Point2D {
                    xy: [5.0, 6.0],
                    point3d_id: Some(7),
                }],
            },
        ],
        points: vec![Point3D {
            id: 7,
            xyz: [0.1, 0.2, 3.0],
            rgb: [1, 2, 3],
            error: 0.5,
            track: vec![
                TrackElement {
                    image_id: 3,
                    point2d_idx: 0,
                },
                TrackElement {
                    image_id: 4,
                    point2d_idx: 0,
                },
            ],
        }],
    }
}

fn colmap_files() -> [Vec<u8>; 3] {
    let dir = scratch().join("seed-colmap");
    std::fs::create_dir_all(&dir).expect("create seed folder");
    write_bin(&colmap_model(), &dir).expect("write COLMAP seed");
    COLMAP_FILES.map(|f| std::fs::read(dir.join(f)).expect("read seed back"))
}

fn splats(n: usize, sh_degree: u32) -> Splats {
    let mut s = Splats::with_capacity(n, sh_degree);
    let k = s.rest_per_channel();
    for i in 0..n {
        let x = i as f32;
        s.means.extend([x, -x, 0.5 * x]);
        s.log_scales.extend([-2.0, -2.5, -3.0]);
        s.rotations.extend([1.0, 0.1 * x, 0.0, 0.0]);
        s.opacities.push(0.25 * x - 0.5);
        s.sh_dc.extend([0.1, 0.2, 0.3]);
        s.sh_rest.extend((0..3 * k).map(|j| j as f32 * 0.01));
    }
    s
}

fn train_state(n: usize, sh_degree: u32) -> TrainState {
    let sh = 3 * cocog_engine::sh_coeffs_per_channel(sh_degree);
    let floats = |per: usize| (0..n * per).map(|i| i as f32 * 0.5).collect::<Vec<f32>>();
    let moments = [3, 3, 4, 1, sh].map(|per| MomentState {
        m: floats(per),
        v: floats(per),
    });
    TrainState {
        iteration: 1200,
        adam_origin: Some(0),
        views: 8,
        downscale: 4,
        params: cocog_engine::GaussianParams {
            sh_degree,
            means: (0..n).map(|i| [i as f32, 1.0, 2.0]).collect(),
            log_scales: vec![[-3.0; 3]; n],
            quats: vec![[1.0, 0.0, 0.0, 0.0]; n],
            opacity_logits: floats(1),
            sh: floats(sh),
        },
        moments,
        grad_accum: floats(1),
        grad_denom: floats(1),
        rng: 0x0123_4567_89ab_cdef,
        order_rng: 42,
        order_stack: vec![3, 1, 2],
        coc: None,
    }
}

/// A cocog checkpoint's lens-model part (h_θ, F, per-view focus and aperture with moments).
fn coc_checkpoint(views: usize) -> cocog_train::CocCheckpoint {
    let moments = |len: usize| MomentState {
        m: vec![0.25; len],
        v: vec![0.5; len],
    };
    cocog_train::CocCheckpoint {
        variant: "lens".into(),
        copies: 4,
        width: 64,
        centred: true,
        modulate_base: false,
        compositor_channels: 8,
        starts: Some([1000, 6000]),
        mlp: vec![0.1; 12],
        mlp_moments: moments(12),
        compositor: vec![-0.2; 6],
        compositor_moments: moments(6),
        focus: Some(cocog_train::FocusState {
            values: vec![1.5; views],
            moments: moments(views),
            apertures: vec![0.01; views],
            aperture_moments: moments(views),
            scale: 2.0,
            origin: [0.1, -0.2, 0.3],
        }),
    }
}

fn scene() -> Scene {
    let pose = |t: f64| {
        [
            [1.0, 0.0, 0.0, t],
            [0.0, 1.0, 0.0, 0.0],
            [0.0, 0.0, 1.0, 0.0],
            [0.0, 0.0, 0.0, 1.0],
        ]
    };
    Scene {
        cameras: vec![SceneCamera {
            id: 1,
            width: 64,
            height: 48,
            fx: 50.0,
            fy: 50.0,
            cx: 32.0,
            cy: 24.0,
        }],
        views: vec![
            View {
                name: "000.png".into(),
                image: "images/000.png".into(),
                camera: 1,
                world_from_camera: pose(0.0),
                split: Split::Train,
                lens: Some(Lens {
                    focus_distance: 2.5,
                    aperture: Some(0.1),
                }),
                depth: Some("depth/000.exr".into()),
            },
            View {
                name: "001.png".into(),
                image: "/abs/001.png".into(),
                camera: 1,
                world_from_camera: pose(0.5),
                split: Split::Test,
                lens: None,
                depth: None,
            },
        ],
        bounds: Some(Bounds {
            near: 0.1,
            far: 10.0,
        }),
        up: Some([0.0, -1.0, 0.0]),
        points: Some("points.ply".into()),
        gaussians: Some("gaussians.ply".into()),
        ..Scene::default()
    }
}

/// Valid inputs for target `name`, written by cocog's own writers, with a file name each.
pub fn seeds(name: &str) -> Vec<(String, Vec<u8>)> {
    let mut out = Vec::new();
    match name {
        "colmap_bin" => {
            for (i, file) in colmap_files().into_iter().enumerate() {
                let mut data = vec![i as u8];
                data.extend(file);
                out.push((COLMAP_FILES[i].to_owned(), data));
            }
        }
        "ply" => {
            let cloud = PointCloud {
                positions: vec![0.0, 1.0, 2.0, -1.0, 0.5, 3.0],
                colors: vec![255, 0, 10, 20, 30, 40],
            };
            out.push((
                "points.ply".into(),
                written("points.ply", |p| {
                    cocog_formats::ply::write_points(p, &cloud).expect("write points")
                }),
            ));
            for degree in [0, 1, 3] {
                let up = (degree == 1).then_some("-y");
                out.push((
                    format!("splats-sh{degree}.ply"),
                    written("splats.ply", |p| {
                        cocog_formats::ply::write_splats(p, &splats(3, degree), up)
                            .expect("write splats")
                    }),
                ));
            }
            // The readers also take ASCII PLY, which no cocog writer produces.
            out.push((
                "points-ascii.ply".into(),
                b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n\
                  property float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\n\
                  end_header\n0 1 2 255 0 10\n-1 0.5 3 20 30 40\n"
                    .to_vec(),
            ));
        }
        "glb" => {
            for degree in [0, 3] {
                out.push((
                    format!("splats-sh{degree}.glb"),
                    written("splats.glb", |p| {
                        cocog_formats::glb::write_glb(p, &splats(3, degree)).expect("write glb")
                    }),
                ));
            }
        }
        "npy" => {
            let view = |t: f64| LlffView {
                world_from_camera: [
                    [1.0, 0.0, 0.0, t],
                    [0.0, 1.0, 0.0, 0.0],
                    [0.0, 0.0, 1.0, 0.0],
                    [0.0, 0.0, 0.0, 1.0],
                ],
                hwf: [48.0, 64.0, 50.0],
                near: 0.5,
                far: 20.0,
            };
            let views = [view(0.0), view(1.0)];
            let f64_file = written("poses_bounds.npy", |p| {
                cocog_formats::llff::write_poses_bounds(p, &views).expect("write npy")
            });
            // The same rows as float32 in Fortran order, which LLFF tools also produce.
            let f32_file = {
                use npyz::WriterBuilder;
                let rows: Vec<f64> = npyz::NpyFile::new(&f64_file[..])
                    .expect("own npy")
                    .into_vec()
                    .expect("own npy data");
                let n = rows.len() / 17;
                let mut buf = Vec::new();
                let mut w = npyz::WriteOptions::new()
                    .default_dtype()
                    .shape(&[n as u64, 17])
                    .order(npyz::Order::Fortran)
                    .writer(&mut buf)
                    .begin_nd()
                    .expect("npy writer");
                for j in 0..17 {
                    for i in 0..n {
                        w.push(&(rows[i * 17 + j] as f32)).expect("npy value");
                    }
                }
                w.finish().expect("npy finish");
                buf
            };
            out.push(("poses_bounds-f64.npy".into(), f64_file));
            out.push(("poses_bounds-f32-fortran.npy".into(), f32_file));
        }
        "checkpoint" => {
            for (n, degree) in [(2, 0), (1, 3)] {
                let dir = scratch().join("seed-checkpoint");
                let mut state = train_state(n, degree);
                // One seed carries a cocog lens model, so its metadata and tensors are fuzzed.
                if degree == 3 {
                    state.coc = Some(coc_checkpoint(state.views as usize));
                }
                let path = state.save(&dir).expect("write checkpoint");
                out.push((
                    format!("state-n{n}-sh{degree}.safetensors"),
                    std::fs::read(path).expect("read seed back"),
                ));
            }
        }
        "scene_json" => {
            let dir = scratch().join("seed-scene");
            std::fs::create_dir_all(&dir).expect("create seed folder");
            scene().save(&dir).expect("write scene");
            let path = dir.join(cocog_pipeline::scene::MANIFEST);
            out.push((
                "scene.json".into(),
                std::fs::read(&path).expect("read back"),
            ));
            Scene::default().save(&dir).expect("write scene");
            out.push((
                "empty.json".into(),
                std::fs::read(&path).expect("read back"),
            ));
        }
        _ => panic!("unknown fuzz target {name}"),
    }
    out
}
