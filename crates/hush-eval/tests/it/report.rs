use hush_eval::{CONVENTIONS, Metrics, Report, Row};

use crate::TempDir;

fn metrics(psnr: f64) -> Metrics {
    Metrics { psnr, ssim: 0.9, mae: 0.01, mse: 1e-4, rel_mse: 2e-3, exposure: 1.0 }
}

fn report() -> Report {
    let mut denoised = Row::new("cbox_v0", "hush|unet", 16, &metrics(35.5), Some(1.25));
    denoised.preview = Some("previews/cbox v0 denoised.png".into());
    Report {
        rows: vec![
            Row::new("cbox_v0", "noisy", 16, &metrics(28.0), None),
            denoised,
            Row::new("cbox_v1", "noisy", 16, &metrics(30.0), None),
            Row::new("cbox_v1", "reference", 16, &metrics(f64::INFINITY), None),
        ],
        notes: vec!["2 threads, CPU".into()],
    }
}

#[test]
fn markdown_has_a_table_per_view_and_the_conventions() {
    let md = report().to_markdown();
    assert!(md.contains(CONVENTIONS) && md.contains("- 2 threads, CPU"));
    assert!(md.contains("## cbox_v0") && md.contains("## cbox_v1") && md.contains("## Mean over 2 views"));
    assert!(md.contains("| hush\\|unet | 16 | 35.50 | 0.9000 | 0.0100 | 1.000e-4 | 2.000e-3 | 1.250 | [png](previews/cbox%20v0%20denoised.png) |"), "{md}");
    assert!(md.contains("| reference | 16 | ∞ |"), "{md}");
    assert!(md.contains("| noisy | 16 | 29.00 |"), "mean of 28 and 30: {md}");
}

#[test]
fn write_creates_markdown_and_json_that_reads_back() {
    let dir = TempDir::new("report");
    let out = dir.path().join("eval");
    let r = report();
    r.write(&out).unwrap();
    let mut files: Vec<String> =
        std::fs::read_dir(&out).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    files.sort();
    assert_eq!(files, ["report.md", "summary.json"]);
    assert_eq!(dir.files(), ["eval"]);

    let json = std::fs::read_to_string(out.join("summary.json")).unwrap();
    assert!(json.contains("\"psnr\": null") && json.contains("\"conventions\""), "{json}");
    let back: Report = serde_json::from_str(&json).unwrap();
    assert_eq!(back, r, "infinite PSNR is written as null and read back as +inf");
}
