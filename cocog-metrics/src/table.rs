//! A plain-text table of a `metrics.json` report, for a terminal.
//!
//! It reads the JSON (not the Rust struct) so the CLI can print a report that came back from a
//! dynamic plugin or from disk.

use serde_json::Value;

/// Metric keys in display order, with their column titles.
const COLUMNS: [(&str, &str); 5] = [
    ("psnr", "PSNR"),
    ("ssim_deblurnerf", "SSIM(DN)"),
    ("ssim_gaussian11", "SSIM(G11)"),
    ("lpips_alex", "LPIPS-A"),
    ("lpips_vgg", "LPIPS-V"),
];

fn cell(v: Option<&Value>, key: &str) -> String {
    match v {
        Some(Value::Number(n)) => {
            let x = n.as_f64().unwrap_or(f64::NAN);
            if key == "psnr" {
                format!("{x:.3}")
            } else {
                format!("{x:.4}")
            }
        }
        // serde_json writes +inf as null; only PSNR can be infinite (identical images).
        Some(Value::Null) if key == "psnr" => "inf".into(),
        _ => "-".into(),
    }
}

/// Renders per-image rows, a mean row and the LPIPS note (if any). Columns appear only when some
/// row has them, so a report without LPIPS prints no empty LPIPS column.
pub fn format_table(report: &Value) -> String {
    let images = report["images"].as_array().cloned().unwrap_or_default();
    let mean = &report["mean"];
    let cols: Vec<(&str, &str)> = COLUMNS
        .into_iter()
        .filter(|(k, _)| mean.get(*k).is_some() || images.iter().any(|i| i.get(*k).is_some()))
        .collect();

    let mut rows: Vec<Vec<String>> = Vec::new();
    let mut header = vec!["image".to_string()];
    header.extend(cols.iter().map(|(_, t)| t.to_string()));
    rows.push(header);
    for img in &images {
        let mut row = vec![img["name"].as_str().unwrap_or("?").to_string()];
        row.extend(cols.iter().map(|(k, _)| cell(img.get(*k), k)));
        rows.push(row);
    }
    let mut mean_row = vec![format!("mean ({})", images.len())];
    mean_row.extend(cols.iter().map(|(k, _)| cell(mean.get(*k), k)));
    rows.push(mean_row);

    let widths: Vec<usize> = (0..rows[0].len())
        .map(|c| rows.iter().map(|r| r[c].len()).max().unwrap_or(0))
        .collect();
    let line = |r: &Vec<String>| {
        let mut s = format!("{:<w$}", r[0], w = widths[0]);
        for (c, v) in r.iter().enumerate().skip(1) {
            s.push_str(&format!("  {v:>w$}", w = widths[c]));
        }
        s.push('\n');
        s
    };
    let rule = format!(
        "{}\n",
        "-".repeat(widths.iter().sum::<usize>() + 2 * (widths.len() - 1))
    );
    let mut out = line(&rows[0]);
    out.push_str(&rule);
    for r in &rows[1..rows.len() - 1] {
        out.push_str(&line(r));
    }
    out.push_str(&rule);
    out.push_str(&line(&rows[rows.len() - 1]));
    if let Some(note) = report["lpips"]["note"].as_str() {
        out.push_str(&format!("note: {note}\n"));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn table_has_a_row_per_image_a_mean_and_only_present_columns() {
        let report = serde_json::json!({
            "images": [
                {"name": "000", "psnr": 20.12345, "ssim_deblurnerf": 0.7, "ssim_gaussian11": 0.8,
                 "lpips_alex": 0.31},
                {"name": "008", "psnr": null, "ssim_deblurnerf": 1.0, "ssim_gaussian11": 1.0,
                 "lpips_alex": 0.0},
            ],
            "mean": {"psnr": null, "ssim_deblurnerf": 0.85, "ssim_gaussian11": 0.9,
                     "lpips_alex": 0.155},
            "lpips": {"note": "hello"},
        });
        let t = format_table(&report);
        let lines: Vec<&str> = t.lines().collect();
        assert_eq!(lines.len(), 7, "{t}");
        assert!(
            lines[0].contains("LPIPS-A") && !lines[0].contains("LPIPS-V"),
            "{t}"
        );
        assert!(
            lines[2].contains("20.123") && lines[2].contains("0.3100"),
            "{t}"
        );
        assert!(lines[3].contains("inf"), "{t}");
        assert!(
            lines[5].starts_with("mean (2)") && lines[5].contains("0.1550"),
            "{t}"
        );
        assert_eq!(lines[6], "note: hello");
    }
}
