//! Image listing, loading in every layout we meet, and downscaling.

mod common;

use cocog_formats::images::{
    downscaled_size, image_size, list_images, load_rgb, prescaled_path, write_downscaled,
};
use image::{GrayImage, ImageBuffer, Rgb, Rgba, RgbaImage};

#[test]
fn loads_16_bit_grey_and_rgba() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let rgb16: ImageBuffer<Rgb<u16>, Vec<u16>> = ImageBuffer::from_fn(4, 3, |x, y| {
        Rgb([x as u16 * 20000, y as u16 * 30000, 65535])
    });
    rgb16.save(d.join("a16.png")).unwrap();
    let img = load_rgb(&d.join("a16.png"), None).unwrap();
    assert_eq!((img.width, img.height), (4, 3));
    assert!(
        (img.data[3 * 5] - 20000.0 / 65535.0).abs() < 1e-6
            && (img.data[3 * 5 + 1] - 30000.0 / 65535.0).abs() < 1e-6
    );

    GrayImage::from_fn(2, 2, |x, _| image::Luma([x as u8 * 255]))
        .save(d.join("g.png"))
        .unwrap();
    assert_eq!(
        load_rgb(&d.join("g.png"), None).unwrap().data,
        vec![0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0]
    );

    RgbaImage::from_pixel(1, 1, Rgba([255, 0, 0, 51]))
        .save(d.join("rgba.png"))
        .unwrap();
    let c = load_rgb(&d.join("rgba.png"), Some([1.0, 1.0, 1.0]))
        .unwrap()
        .data;
    assert!(
        (c[0] - 1.0).abs() < 1e-6 && (c[1] - 0.8).abs() < 1e-6,
        "{c:?}"
    );
    assert_eq!(
        load_rgb(&d.join("rgba.png"), None).unwrap().data,
        vec![1.0, 0.0, 0.0]
    );

    std::fs::write(d.join("z.jpg"), b"not a jpeg").unwrap();
    std::fs::write(d.join("notes.txt"), b"").unwrap();
    let names: Vec<String> = list_images(d)
        .unwrap()
        .iter()
        .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
        .collect();
    assert_eq!(names, ["a16.png", "g.png", "rgba.png", "z.jpg"]);
    let e = load_rgb(&d.join("z.jpg"), None).unwrap_err().to_string();
    assert!(e.contains("z.jpg") && e.contains("decode"), "{e}");
    let e = image_size(&d.join("missing.png")).unwrap_err().to_string();
    assert!(
        e.contains("missing.png") && e.contains("does not exist"),
        "{e}"
    );
}

#[test]
fn downscale_is_an_area_average_keeping_bit_depth() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let src: ImageBuffer<Rgb<u8>, Vec<u8>> = ImageBuffer::from_fn(8, 6, |x, y| {
        Rgb([(x * 30) as u8, (y * 40) as u8, ((x * y) % 256) as u8])
    });
    src.save(d.join("s.png")).unwrap();
    assert_eq!(
        write_downscaled(&d.join("s.png"), &d.join("o.png"), 2).unwrap(),
        (4, 3)
    );
    let out = image::open(d.join("o.png")).unwrap();
    assert_eq!(out.color(), image::ColorType::Rgb8);
    let out = out.to_rgb8();
    for (x, y, p) in out.enumerate_pixels() {
        for c in 0..3 {
            let mean: f64 = (0..2)
                .flat_map(|dy| (0..2).map(move |dx| (dx, dy)))
                .map(|(dx, dy)| f64::from(src.get_pixel(2 * x + dx, 2 * y + dy).0[c]))
                .sum::<f64>()
                / 4.0;
            assert!(
                (f64::from(p.0[c]) - mean).abs() <= 0.5 + 1e-9,
                "({x},{y}) c{c}: {} vs {mean}",
                p.0[c]
            );
        }
    }
    // A factor that does not divide: INRIA-style rounded size, and a flat image stays flat.
    let flat: ImageBuffer<Rgb<u16>, Vec<u16>> =
        ImageBuffer::from_pixel(10, 7, Rgb([1234, 40000, 7]));
    flat.save(d.join("f.png")).unwrap();
    assert_eq!(downscaled_size(10, 7, 3), (3, 2));
    write_downscaled(&d.join("f.png"), &d.join("f3.png"), 3).unwrap();
    let f3 = image::open(d.join("f3.png")).unwrap();
    assert_eq!(f3.color(), image::ColorType::Rgb16);
    assert!(f3.to_rgb16().pixels().all(|p| p.0 == [1234, 40000, 7]));
}

#[test]
fn prescaled_folder_is_found_and_bench_images_listed() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::create_dir(dir.path().join("images_4")).unwrap();
    std::fs::write(dir.path().join("images_4/a.png"), b"").unwrap();
    let img = dir.path().join("images/a.png");
    assert_eq!(
        prescaled_path(dir.path(), &img, 4),
        Some(dir.path().join("images_4/a.png"))
    );
    assert_eq!(prescaled_path(dir.path(), &img, 2), None);
    assert_eq!(prescaled_path(dir.path(), &img, 1), None);
    for scene in common::dev_scenes() {
        let list = list_images(&scene.join("images")).unwrap();
        assert_eq!(list.len(), 24);
        assert_eq!(image_size(&list[0]).unwrap(), (400, 300));
        let rgb = load_rgb(&list[0], None).unwrap();
        assert!(rgb.data.iter().all(|v| (0.0..=1.0).contains(v)));
    }
}

#[test]
fn a_folder_where_a_photo_should_be_is_named_as_one() {
    let dir = tempfile::tempdir().unwrap();
    let e = cocog_formats::images::image_size(dir.path())
        .unwrap_err()
        .to_string();
    assert!(e.contains("is a folder"), "{e}");
    let e = cocog_formats::images::image_size(&dir.path().join("none.png"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("does not exist"), "{e}");
}
