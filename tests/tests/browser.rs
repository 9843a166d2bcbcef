//! cocog's exports in a real web 3DGS renderer: Babylon.js (`tests/browser`, npm) loads the
//! `.ply`, the `.glb` (`KHR_gaussian_splatting`) and the `.spz` in headless Chromium and renders the camera
//! cocog rendered; the screenshots must match cocog's own render. The scene is made to catch
//! convention slips: long thin Gaussians in every orientation (rotation order) and strong
//! view-dependent colour to degree 3 (SH layout). A PLY with the quaternion's x and z swapped,
//! or with its SH coefficients stored coefficient-major instead of channel-major, must fail.
//!
//! Needs Node.js, `npm ci` in tests/browser and Debian's chromium (`.ci/run` installs them);
//! without CI=true a missing one skips with the reason.

use std::path::Path;
use std::process::Command;

use cocog_formats::rng::SplitMix64;
use cocog_formats::splats::Splats;
use cocog_tests::{browser_dir, cocog, node_package_missing, path_str, skip_because, stderr};
use serde_json::json;

const W: u32 = 160;
const H: u32 = 120;
const F: f64 = 130.0;
/// Measured: 24.7 dB for both files (renderer differences: Babylon's splat footprint and
/// cut-off, 8-bit colour, its own depth sort); with the rotation broken 13.7 dB, with the SH
/// order broken 15.5 dB. The threshold sits 3.7 dB below the correct files and 5.5 above
/// the broken ones.
const MIN_PSNR: f64 = 21.0;

/// Why the browser test cannot run here, if it cannot.
fn missing() -> Option<String> {
    let chromium = std::env::var("COCOG_CHROMIUM").unwrap_or_else(|_| "/usr/bin/chromium".into());
    if !Path::new(&chromium).exists() {
        return Some(format!(
            "no Chromium at {chromium} (apt-get install chromium)"
        ));
    }
    node_package_missing("babylonjs")
}

/// 400 long thin Gaussians in front of an identity camera, SH degree 3 with large
/// view-dependent terms.
fn scene_splats() -> Splats {
    let mut rng = SplitMix64::new(3);
    let mut u = |lo: f64, hi: f64| (lo + (hi - lo) * rng.next_f64()) as f32;
    let mut s = Splats::with_capacity(400, 3);
    for _ in 0..400 {
        let z = u(2.0, 4.0);
        s.means.extend([u(-0.6, 0.6) * z, u(-0.45, 0.45) * z, z]);
        s.log_scales
            .extend([u(0.08, 0.2).ln(), u(0.01, 0.02).ln(), u(0.01, 0.02).ln()]);
        let q = [u(-1.0, 1.0), u(-1.0, 1.0), u(-1.0, 1.0), u(-1.0, 1.0)];
        let n = q.iter().map(|v| v * v).sum::<f32>().sqrt();
        s.rotations.extend(q.map(|v| v / n));
        s.opacities.push(u(1.0, 3.0));
        s.sh_dc.extend([u(-1.2, 1.2), u(-1.2, 1.2), u(-1.2, 1.2)]);
        s.sh_rest.extend((0..45).map(|_| u(-0.6, 0.6)));
    }
    s
}

/// A scene directory with `splats` as its trained Gaussians and one identity view.
fn write_scene(dir: &Path, splats: &Splats) {
    std::fs::create_dir_all(dir.join("images")).unwrap();
    image::RgbImage::new(W, H)
        .save(dir.join("images/a.png"))
        .unwrap();
    let identity = [
        [1.0, 0.0, 0.0, 0.0],
        [0.0, 1.0, 0.0, 0.0],
        [0.0, 0.0, 1.0, 0.0],
        [0.0, 0.0, 0.0, 1.0],
    ];
    let scene = json!({
        "format": "cocog.scene", "version": "1.1",
        "cameras": [{"id": 1, "width": W, "height": H, "fx": F, "fy": F,
                     "cx": f64::from(W) / 2.0, "cy": f64::from(H) / 2.0}],
        "views": [{"name": "a.png", "image": "images/a.png", "camera": 1,
                   "world_from_camera": identity, "split": "test"}],
        "gaussians": "gaussians.ply",
        "history": [],
    });
    std::fs::write(dir.join("scene.json"), scene.to_string()).unwrap();
    cocog_formats::ply::write_splats(&dir.join("gaussians.ply"), splats, None).unwrap();
}

/// The camera of the view in the file's coordinates: `to_file` maps cocog's world there.
fn camera_json(path: &Path, to_file: impl Fn([f64; 3]) -> [f64; 3]) {
    // OpenCV camera at the origin looking down +z, y down.
    let cam = json!({
        "width": W, "height": H,
        "position": to_file([0.0, 0.0, 0.0]),
        "target": to_file([0.0, 0.0, 1.0]),
        "up": to_file([0.0, -1.0, 0.0]),
        "fov_y": 2.0 * (f64::from(H) / (2.0 * F)).atan(),
    });
    std::fs::write(path, cam.to_string()).unwrap();
}

fn shoot(file: &Path, camera: &Path, out: &Path) {
    let o = Command::new("node")
        .arg(browser_dir().join("shoot.mjs"))
        .args([file, camera, out])
        .output()
        .expect("run node");
    assert!(
        o.status.success(),
        "shoot.mjs {}: {}\n{}",
        file.display(),
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
}

fn psnr(a: &Path, b: &Path) -> f64 {
    let (a, b) = (
        image::open(a).unwrap().to_rgb8(),
        image::open(b).unwrap().to_rgb8(),
    );
    assert_eq!(a.dimensions(), b.dimensions());
    let mse = a
        .as_raw()
        .iter()
        .zip(b.as_raw())
        .map(|(x, y)| (f64::from(*x) - f64::from(*y)).powi(2) / 255.0f64.powi(2))
        .sum::<f64>()
        / a.as_raw().len() as f64;
    10.0 * (1.0 / mse).log10()
}

#[test]
fn exports_render_in_a_web_viewer_as_cocog_renders_them() {
    if skip_because(missing()) {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let t = |name: &str| tmp.path().join(name);
    let splats = scene_splats();
    write_scene(&t("scene"), &splats);
    let (ply, glb, spz) = (t("scene.ply"), t("scene.glb"), t("scene.spz"));
    for (format, out) in [("ply", &ply), ("glb", &glb), ("spz", &spz)] {
        let o = cocog(&[
            "export",
            path_str(&t("scene")),
            "--format",
            format,
            "-o",
            path_str(out),
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
    }
    let o = cocog(&["render", path_str(&t("scene")), "-o", path_str(&t("cocog"))]);
    assert!(o.status.success(), "{}", stderr(&o));
    let reference = t("cocog").join("a.png");

    // The PLY keeps cocog's world; the glTF is it turned 180° about z (its +Y up), the SPZ
    // 180° about x (its RUB axes; Babylon's own SPZ parser, not Niantic's library).
    camera_json(&t("cam-ply.json"), |p| p);
    camera_json(&t("cam-glb.json"), |p| [-p[0], -p[1], p[2]]);
    camera_json(&t("cam-spz.json"), |p| [p[0], -p[1], -p[2]]);
    shoot(&ply, &t("cam-ply.json"), &t("ply.png"));
    shoot(&glb, &t("cam-glb.json"), &t("glb.png"));
    shoot(&spz, &t("cam-spz.json"), &t("spz.png"));
    let (p_ply, p_glb, p_spz) = (
        psnr(&reference, &t("ply.png")),
        psnr(&reference, &t("glb.png")),
        psnr(&reference, &t("spz.png")),
    );
    eprintln!("Babylon.js vs cocog: PLY {p_ply:.2} dB, glTF {p_glb:.2} dB, SPZ {p_spz:.2} dB");
    assert!(p_ply >= MIN_PSNR, "PLY: {p_ply:.2} dB < {MIN_PSNR}");
    assert!(p_glb >= MIN_PSNR, "glTF: {p_glb:.2} dB < {MIN_PSNR}");
    assert!(p_spz >= MIN_PSNR, "SPZ: {p_spz:.2} dB < {MIN_PSNR}");

    // The same comparison catches a PLY written with the wrong conventions.
    let mut rotated = splats.clone();
    for q in rotated.rotations.chunks_exact_mut(4) {
        q.swap(1, 3);
    }
    let mut transposed = splats;
    for row in transposed.sh_rest.chunks_exact_mut(45) {
        let channel_major: Vec<f32> = row.to_vec();
        for c in 0..3 {
            for j in 0..15 {
                row[j * 3 + c] = channel_major[c * 15 + j];
            }
        }
    }
    for (name, broken) in [("rotation", rotated), ("sh-order", transposed)] {
        let file = t(&format!("{name}.ply"));
        cocog_formats::ply::write_splats(&file, &broken, None).unwrap();
        let shot = t(&format!("{name}.png"));
        shoot(&file, &t("cam-ply.json"), &shot);
        let p = psnr(&reference, &shot);
        eprintln!("Babylon.js vs cocog with the {name} broken: {p:.2} dB");
        assert!(
            p < MIN_PSNR,
            "a PLY with the {name} broken must fail ({p:.2} dB)"
        );
    }
}
