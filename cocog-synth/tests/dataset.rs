//! End-to-end checks of generated datasets: the three pose files agree, the images are what
//! the thin-lens and pinhole renders say, generation is deterministic and all-or-nothing.

use std::collections::BTreeMap;
use std::path::Path;

use cocog_engine::reference::render;
use cocog_formats::colmap::{Pinhole, read_model};
use cocog_formats::llff::{read_hold_marker, read_poses_bounds};
use cocog_formats::nerf::read_dataset;
use cocog_formats::pose::Mat4;
use cocog_synth::lens::quantize;
use cocog_synth::sparse::project;
use cocog_synth::{
    Split, SynthConfig, SynthError, render_thin_lens, tabletop, view_specs, write_defocus_dataset,
};

fn max_pose_diff(a: &Mat4, b: &Mat4) -> f64 {
    a.iter()
        .flatten()
        .zip(b.iter().flatten())
        .fold(0.0, |m, (x, y)| m.max((x - y).abs()))
}

fn load_rgb(path: &Path) -> (u32, u32, Vec<u8>) {
    let img = image::open(path).unwrap().to_rgb8();
    (img.width(), img.height(), img.into_raw())
}

/// Sum of squared horizontal and vertical differences of the mean channel: lower is blurrier.
fn gradient_energy(w: u32, h: u32, rgb: &[u8]) -> f64 {
    let (w, h) = (w as usize, h as usize);
    let lum = |x: usize, y: usize| {
        let p = &rgb[3 * (y * w + x)..3 * (y * w + x) + 3];
        p.iter().map(|&v| f64::from(v)).sum::<f64>() / 3.0
    };
    let mut e = 0.0;
    for y in 0..h - 1 {
        for x in 0..w - 1 {
            e += (lum(x + 1, y) - lum(x, y)).powi(2) + (lum(x, y + 1) - lum(x, y)).powi(2);
        }
    }
    e
}

/// Every file under `dir`, by relative path.
fn tree(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    let mut out = BTreeMap::new();
    let mut stack = vec![dir.to_owned()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else {
                let rel = p.strip_prefix(dir).unwrap().to_string_lossy().into_owned();
                out.insert(rel, std::fs::read(&p).unwrap());
            }
        }
    }
    out
}

#[test]
fn poses_agree_across_colmap_llff_and_transforms() {
    let tmp = tempfile::tempdir().unwrap();
    let ds = tmp.path().join("ds");
    let cfg = SynthConfig::tiny(3);
    let summary = write_defocus_dataset(&ds, &cfg).unwrap();
    assert_eq!((summary.views, summary.test_views), (10, 2));
    assert_eq!(read_hold_marker(&ds).unwrap(), Some(8));

    let truth = view_specs(&cfg);
    let model = read_model(&ds.join("sparse/0")).unwrap();
    let llff = read_poses_bounds(&ds.join("poses_bounds.npy")).unwrap();
    let frames = read_dataset(&ds).unwrap();
    assert_eq!((model.images.len(), llff.len(), frames.len()), (10, 10, 10));
    let mut images = model.images.clone();
    images.sort_by(|a, b| a.name.cmp(&b.name));
    let cam = model.camera(1).unwrap().pinhole().unwrap();
    let t = &truth[0].camera;
    assert_eq!(
        cam,
        Pinhole {
            fx: t.fx,
            fy: t.fy,
            cx: t.cx,
            cy: t.cy
        }
    );

    for (i, v) in truth.iter().enumerate() {
        let want = &v.camera.world_from_camera;
        assert_eq!(images[i].name, v.name);
        assert!(max_pose_diff(&images[i].world_from_camera(), want) < 1e-6);
        assert!(max_pose_diff(&llff[i].world_from_camera, want) < 1e-6);
        assert!(max_pose_diff(&frames[i].world_from_camera, want) < 1e-6);
        assert_eq!(llff[i].hwf, [36.0, 48.0, t.fx]);
        assert!(0.3 < llff[i].near && llff[i].near < 1.0, "{:?}", llff[i]);
        assert!(2.5 < llff[i].far && llff[i].far < 4.0, "{:?}", llff[i]);
        assert_eq!(frames[i].file_path, format!("images/{}", v.name));
        assert_eq!(frames[i].split.as_deref(), Some(v.split.as_str()));
        // JSON keeps 17 significant digits; the last may differ after parsing.
        let focus = |f: Option<f64>| f.map(|s| (s * 1e12).round());
        assert_eq!(
            focus(frames[i].focus_distance),
            focus(summary.focus_distances[i])
        );
        assert_eq!(
            focus(frames[i].focus_distance),
            focus(v.lens.map(|l| l.focus_distance))
        );
        let p = frames[i].camera.pinhole(48.0, 36.0).unwrap();
        assert_eq!(p, cam);
        assert_eq!(load_rgb(&ds.join("images").join(&v.name)).0, 48);
    }

    // Points: seen by two or more train views, observed where they project (up to noise).
    assert!(
        model.points.len() > 20,
        "only {} points",
        model.points.len()
    );
    for p in &model.points {
        assert!(p.track.len() >= 2);
        for t in &p.track {
            let img = model.images.iter().find(|i| i.id == t.image_id).unwrap();
            let view = truth.iter().find(|v| v.name == img.name).unwrap();
            assert_eq!(view.split, Split::Train);
            let obs = img.points2d[t.point2d_idx as usize];
            assert_eq!(obs.point3d_id, Some(p.id));
            let (xy, _) = project(&view.camera, p.xyz).unwrap();
            assert!((xy[0] - obs.xy[0]).hypot(xy[1] - obs.xy[1]) < 3.0);
        }
    }
}

#[test]
fn train_views_are_defocused_and_test_views_are_pinhole_renders() {
    let tmp = tempfile::tempdir().unwrap();
    let ds = tmp.path().join("ds");
    let cfg = SynthConfig::tiny(5);
    write_defocus_dataset(&ds, &cfg).unwrap();
    let scene = tabletop(cfg.seed);
    for v in view_specs(&cfg) {
        let (w, h, file) = load_rgb(&ds.join("images").join(&v.name));
        let pinhole = quantize(&render(&scene.gaussians, &v.camera, scene.background).color);
        match v.split {
            Split::Test => assert_eq!(file, pinhole, "{}", v.name),
            Split::Train => {
                let lens = render_thin_lens(
                    &scene.gaussians,
                    &v.camera,
                    v.lens,
                    cfg.lens_samples,
                    scene.background,
                    cfg.blur_space,
                );
                assert_eq!(file, quantize(&lens), "{}", v.name);
                let changed = file
                    .iter()
                    .zip(&pinhole)
                    .filter(|(a, b)| a.abs_diff(**b) > 8)
                    .count();
                assert!(changed > file.len() / 50, "{} barely differs", v.name);
                let (blurred, sharp) = (
                    gradient_energy(w, h, &file),
                    gradient_energy(w, h, &pinhole),
                );
                assert!(blurred < 0.9 * sharp, "{}: {blurred} vs {sharp}", v.name);
            }
        }
    }
}

#[test]
fn same_seed_same_bytes_other_seed_other_images() {
    let tmp = tempfile::tempdir().unwrap();
    let cfg = SynthConfig {
        views: 4,
        hold: 2,
        ..SynthConfig::tiny(11)
    };
    let a = tmp.path().join("a");
    let b = tmp.path().join("b");
    let c = tmp.path().join("c");
    write_defocus_dataset(&a, &cfg).unwrap();
    // A different thread count must not change a byte either.
    write_defocus_dataset(&b, &SynthConfig { threads: 1, ..cfg }).unwrap();
    write_defocus_dataset(&c, &SynthConfig { seed: 12, ..cfg }).unwrap();
    let (ta, tb, tc) = (tree(&a), tree(&b), tree(&c));
    assert_eq!(ta.len(), 4 + 1 + 1 + 3 + 2);
    assert_eq!(ta, tb);
    for name in ["000.png", "001.png"] {
        let key = format!("images/{name}");
        assert_ne!(ta[&key], tc[&key], "{key}");
    }
}

#[test]
fn existing_directories_and_bad_configs_are_refused_without_leftovers() {
    let tmp = tempfile::tempdir().unwrap();
    let ds = tmp.path().join("ds");
    std::fs::create_dir(&ds).unwrap();
    std::fs::write(ds.join("keep.txt"), b"mine").unwrap();
    let cfg = SynthConfig {
        views: 2,
        ..SynthConfig::tiny(1)
    };
    let err = write_defocus_dataset(&ds, &cfg).unwrap_err();
    assert!(matches!(err, SynthError::Exists(_)), "{err}");
    assert_eq!(tree(&ds).len(), 1);
    assert_eq!(std::fs::read(ds.join("keep.txt")).unwrap(), b"mine");

    let fresh = tmp.path().join("fresh");
    let err = write_defocus_dataset(&fresh, &SynthConfig { hold: 1, ..cfg }).unwrap_err();
    assert!(matches!(err, SynthError::Config(_)), "{err}");
    let err = write_defocus_dataset(&tmp.path().join("no/such/parent/x"), &cfg).unwrap_err();
    assert!(matches!(err, SynthError::Io { .. }), "{err}");
    let left: Vec<_> = std::fs::read_dir(tmp.path())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(left, ["ds"]);
}
