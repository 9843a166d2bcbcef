//! Support for the end-to-end tests: build the `cocog` binary and plugin libraries with
//! the same cargo and profile as the test itself, and run them.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::Mutex;

/// `target/<profile>`: the test binary lives in `target/<profile>/deps/`.
pub fn target_dir() -> PathBuf {
    let exe = std::env::current_exe().expect("test executable path");
    exe.parent()
        .and_then(Path::parent)
        .expect("test binary sits in target/<profile>/deps")
        .to_path_buf()
}

fn profile() -> String {
    target_dir()
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "debug".to_owned())
}

static BUILD: Mutex<()> = Mutex::new(());

/// Builds workspace packages (a no-op when `cargo test --workspace` already did).
pub fn build(packages: &[&str]) {
    let _guard = BUILD.lock().unwrap_or_else(|e| e.into_inner());
    let profile = profile();
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".to_owned());
    let mut cmd = Command::new(cargo);
    cmd.arg("build").arg("--quiet");
    cmd.arg("--profile")
        .arg(if profile == "debug" { "dev" } else { &profile });
    for p in packages {
        cmd.arg("-p").arg(p);
    }
    cmd.current_dir(env!("CARGO_MANIFEST_DIR"));
    let status = cmd.status().expect("run cargo build");
    assert!(status.success(), "cargo build {packages:?} failed");
}

/// Path of the `cocog` binary, built if needed.
pub fn cocog_bin() -> PathBuf {
    build(&["cocog-cli"]);
    target_dir().join(format!("cocog{}", std::env::consts::EXE_SUFFIX))
}

/// Path of a workspace cdylib, built if needed. `package` is the Cargo package name.
pub fn cdylib(package: &str) -> PathBuf {
    build(&[package]);
    let stem = package.replace('-', "_");
    target_dir().join(format!(
        "{}{stem}{}",
        std::env::consts::DLL_PREFIX,
        std::env::consts::DLL_SUFFIX
    ))
}

/// Runs `cocog` with `args`, without plugin paths from the caller's environment.
pub fn cocog(args: &[&str]) -> Output {
    Command::new(cocog_bin())
        .args(args)
        .env_remove("COCOG_PLUGIN_PATH")
        .env_remove("RUST_BACKTRACE")
        .output()
        .expect("run cocog")
}

pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

pub fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// Names in `dir`, sorted: to check nothing half-written was left behind.
pub fn listing(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .map(|rd| {
            rd.filter_map(Result::ok)
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .collect()
        })
        .unwrap_or_default();
    v.sort();
    v
}

/// Whether a test whose outside tool is missing (`why`) should skip: it prints the reason and
/// skips, except under `CI=true`, where the tool must be there (`.ci/run` installs every one) and
/// its absence fails the test.
pub fn skip_because(why: Option<String>) -> bool {
    let Some(why) = why else { return false };
    assert!(
        std::env::var("CI").as_deref() != Ok("true"),
        "CI=true but this test cannot run: {why}"
    );
    eprintln!("skipped: {why}");
    true
}

/// `tests/browser`: the Node project of the web-viewer and SPZ reference checks.
pub fn browser_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("browser")
}

/// Why Node cannot load `package` from `tests/browser`, if it cannot.
pub fn node_package_missing(package: &str) -> Option<String> {
    if Command::new("node").arg("--version").output().is_err() {
        return Some("no Node.js (apt-get install nodejs npm)".into());
    }
    if !browser_dir().join("node_modules").join(package).is_dir() {
        return Some(format!(
            "tests/browser has no node_modules/{package} (npm ci --prefix tests/browser)"
        ));
    }
    None
}

/// `../shared` beside the workspace, if this checkout has it.
pub fn shared_dir() -> Option<PathBuf> {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared");
    p.is_dir().then(|| p.canonicalize().unwrap_or(p))
}

/// A small scene written by hand: `n` cameras on a circle of `radius` around `centre`
/// looking inward, plus a point cloud, so stages have something real to transform.
pub fn write_tiny_scene(dir: &Path, n: usize, centre: [f64; 3], radius: f64) {
    use serde_json::json;
    std::fs::create_dir_all(dir).expect("mkdir scene");
    let views: Vec<_> = (0..n)
        .map(|i| {
            let a = i as f64 / n as f64 * std::f64::consts::TAU;
            let (s, c) = a.sin_cos();
            // Camera z (forward) points at the centre; y is world -z (down); x = y × z.
            let z = [-c, -s, 0.0];
            let y = [0.0, 0.0, -1.0];
            let x = [
                y[1] * z[2] - y[2] * z[1],
                y[2] * z[0] - y[0] * z[2],
                y[0] * z[1] - y[1] * z[0],
            ];
            let t = [centre[0] + radius * c, centre[1] + radius * s, centre[2]];
            json!({
                "name": format!("{i:03}"),
                "image": format!("/nonexistent/images/{i:03}.png"),
                "camera": 1,
                "world_from_camera": [
                    [x[0], y[0], z[0], t[0]],
                    [x[1], y[1], z[1], t[1]],
                    [x[2], y[2], z[2], t[2]],
                    [0.0, 0.0, 0.0, 1.0]
                ],
                "split": if i % 8 == 0 { "test" } else { "train" },
                "lens": { "focus_distance": radius, "aperture": 10.0 },
            })
        })
        .collect();
    let scene = json!({
        "format": "cocog.scene",
        "version": "1.0",
        "cameras": [{ "id": 1, "width": 40, "height": 30, "fx": 40.0, "fy": 40.0, "cx": 20.0, "cy": 15.0 }],
        "views": views,
        "bounds": { "near": 0.5 * radius, "far": 2.0 * radius },
        "points": "points.ply",
    });
    std::fs::write(dir.join("scene.json"), scene.to_string()).expect("write scene.json");
    let cloud = cocog_formats::PointCloud {
        positions: vec![
            centre[0] as f32,
            centre[1] as f32,
            centre[2] as f32,
            (centre[0] + 1.0) as f32,
            centre[1] as f32,
            (centre[2] - 0.5) as f32,
        ],
        colors: vec![255, 0, 0, 0, 255, 0],
    };
    cocog_formats::ply::write_points(&dir.join("points.ply"), &cloud).expect("write points.ply");
}

/// A scene with one trained Gaussian, so `export` has something to write.
pub fn scene_with_gaussians(dir: &Path) {
    write_tiny_scene(dir, 4, [0.0; 3], 1.0);
    let splats = cocog_formats::Splats {
        means: vec![0.0; 3],
        log_scales: vec![-2.0; 3],
        rotations: vec![1.0, 0.0, 0.0, 0.0],
        opacities: vec![0.0],
        sh_dc: vec![0.5; 3],
        sh_rest: Vec::new(),
        sh_degree: 0,
    };
    cocog_formats::ply::write_splats(&dir.join("gaussians.ply"), &splats, None).unwrap();
    let manifest = dir.join("scene.json");
    let mut scene: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&manifest).unwrap()).unwrap();
    scene["gaussians"] = "gaussians.ply".into();
    std::fs::write(&manifest, scene.to_string()).unwrap();
}

pub fn path_str(p: &Path) -> &str {
    p.to_str().expect("test paths are UTF-8")
}
