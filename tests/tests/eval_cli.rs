//! `cocog eval --pred DIR --gt DIR` leaves the user's prediction folder alone: the scores go
//! to stdout unless -o names a file.

use cocog_tests::{cocog, stdout};

fn image(path: &std::path::Path, shade: u8) {
    let img = image::RgbImage::from_fn(16, 12, |x, y| {
        image::Rgb([
            shade.wrapping_add((x * 7 + y * 3) as u8),
            shade,
            255 - shade,
        ])
    });
    img.save(path).unwrap();
}

#[test]
fn scoring_folders_writes_no_file_into_the_predictions() {
    let tmp = tempfile::tempdir().unwrap();
    let (pred, gt) = (tmp.path().join("pred"), tmp.path().join("gt"));
    std::fs::create_dir_all(&pred).unwrap();
    std::fs::create_dir_all(&gt).unwrap();
    image(&pred.join("000.png"), 40);
    image(&gt.join("000.png"), 44);
    let (p, g) = (pred.display().to_string(), gt.display().to_string());
    let out = cocog(&["eval", "--pred", &p, "--gt", &g, "--lpips", "off"]);
    assert!(out.status.success(), "{out:?}");
    assert!(
        stdout(&out).contains("PSNR"),
        "the table goes to stdout: {}",
        stdout(&out)
    );
    let files: Vec<_> = std::fs::read_dir(&pred).unwrap().collect();
    assert_eq!(files.len(), 1, "only the prediction stays in its folder");

    let out = cocog(&["eval", "--pred", &p, "--gt", &g, "--lpips", "off", "--json"]);
    assert!(out.status.success());
    let v: serde_json::Value = serde_json::from_str(&stdout(&out)).unwrap();
    assert!(v["mean"]["psnr"].as_f64().unwrap() > 20.0, "{v}");

    let file = tmp.path().join("scores.json");
    let f = file.display().to_string();
    let out = cocog(&["eval", "--pred", &p, "--gt", &g, "--lpips", "off", "-o", &f]);
    assert!(out.status.success());
    assert!(file.is_file(), "-o names where the scores go");
    assert_eq!(std::fs::read_dir(&pred).unwrap().count(), 1);
}
