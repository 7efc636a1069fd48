use hush_eval::{CONVENTIONS, Figure, FigureImage, FigureKind, Metrics, Report, Row, SCHEMA, Skipped};

use crate::TempDir;

fn metrics(psnr: f64) -> Metrics {
    Metrics {
        psnr,
        ssim: 0.9,
        mae: 0.01,
        mse: 1e-4,
        rel_mse: 2e-3,
        ms_ssim: None,
        flip: None,
        color_shift: None,
        exposure: 1.0,
    }
}

fn row(view: &str, method: &str, spp: u32, psnr: f64, render: Option<f64>, denoise: Option<f64>) -> Row {
    let mut r = Row::new(view, method, spp, &metrics(psnr));
    r.render_seconds = render;
    r.denoise_seconds = denoise;
    r
}

pub fn report() -> Report {
    let mut denoised = row("cbox_v0", "hush|unet", 16, 35.5, Some(2.0), Some(1.25));
    denoised.preview = Some("previews/cbox v0 denoised.png".into());
    denoised.ms_ssim = Some(0.975);
    Report {
        rows: vec![
            row("cbox_v0", "reference", 1024, f64::INFINITY, Some(60.0), None),
            row("cbox_v0", "noisy", 16, 28.0, Some(2.0), None),
            denoised,
            row("cbox_v1", "noisy", 16, 30.0, Some(2.5), None),
        ],
        notes: vec!["2 threads, CPU".into()],
        skipped: vec![Skipped {
            method: "bm3d".into(),
            reason: "the Python package bm3d is not installed".into(),
            install: Some("cargo xtask eval --setup".into()),
        }],
        figures: vec![],
        viewers: vec![],
    }
}

#[test]
fn markdown_has_the_conventions_tables_per_view_and_means() {
    let md = report().to_markdown();
    assert!(md.contains(CONVENTIONS) && md.contains("- 2 threads, CPU"));
    assert!(md.contains("## cbox_v0: all rows") && md.contains("## cbox_v1: all rows"), "{md}");
    assert!(md.contains("## Mean over 2 views"), "{md}");
    assert!(
        md.contains(
            "| hush\\|unet | 16 | 35.50 | 0.9000 | 0.9750 | 0.0100 | 1.000e-4 | 2.000e-3 |  | 2.000 | 1.250 | \
             [png](previews/cbox%20v0%20denoised.png) |"
        ),
        "{md}"
    );
    assert!(md.contains("| reference | 1024 | ∞ |"), "{md}");
    assert!(md.contains("| noisy | 16 | 29.00 |"), "mean of 28 and 30: {md}");
    assert!(
        md.contains("- bm3d: skipped: the Python package bm3d is not installed. Install: `cargo xtask eval --setup`")
    );
}

/// Tables 8.1–8.3 of the thesis: per scene, one row per method (the noisy input first, no reference), columns
/// denoising time, MAE, MSE, PSNR, SSIM, at the lowest spp a denoiser ran at.
#[test]
fn thesis_tables_have_the_thesis_columns_and_a_row_per_method() {
    let r = report();
    assert_eq!(r.table_spp(), Some(16));
    let md = r.to_markdown();
    let start = md.find("## cbox_v0 at 16 spp (as the thesis's Tables 8.1–8.3)").expect(&md);
    let table: Vec<&str> = md[start..].lines().skip(2).take_while(|l| l.starts_with('|')).collect();
    assert_eq!(
        table,
        [
            "| method | denoising time (s) | MAE ↓ | MSE ↓ | PSNR (dB) ↑ | SSIM ↑ |",
            "|---|---:|---:|---:|---:|---:|",
            "| noisy |  | 0.0100 | 1.000e-4 | 28.00 | 0.9000 |",
            "| hush\\|unet | 1.250 | 0.0100 | 1.000e-4 | 35.50 | 0.9000 |",
        ]
    );
    assert!(md.contains("## cbox_v1 at 16 spp"), "{md}");
}

#[test]
fn write_creates_every_file_and_json_that_reads_back() {
    let dir = TempDir::new("report");
    let out = dir.path().join("eval");
    let r = report();
    r.write(&out).unwrap();
    let mut files: Vec<String> =
        std::fs::read_dir(&out).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    files.sort();
    assert_eq!(
        files,
        [
            "error_vs_time.csv",
            "error_vs_time_one_minus_ssim.svg",
            "error_vs_time_rel_mse.svg",
            "report.html",
            "report.md",
            "summary.json"
        ]
    );
    assert_eq!(dir.files(), ["eval"]);

    let json = std::fs::read_to_string(out.join("summary.json")).unwrap();
    assert!(json.contains("\"psnr\": null") && json.contains("\"conventions\""), "{json}");
    let value: serde_json::Value = serde_json::from_str(&json).unwrap();
    assert_eq!(value["schema"], SCHEMA);
    assert_eq!(value["rows"][2]["denoise_seconds"], 1.25);
    assert_eq!(value["rows"][2]["render_seconds"], 2.0);
    assert!(value["rows"][1]["denoise_seconds"].is_null() && value["rows"][1]["flip"].is_null());
    assert_eq!(value["skipped"][0]["install"], "cargo xtask eval --setup");
    let back: Report = serde_json::from_str(&json).unwrap();
    assert_eq!(back, r, "infinite PSNR is written as null and read back as +inf");
}

#[test]
fn a_figure_whose_file_is_missing_is_an_error_naming_it() {
    let dir = TempDir::new("missing-figure");
    let mut r = report();
    r.figures.push(Figure {
        kind: FigureKind::Other,
        title: "crops".into(),
        images: vec![FigureImage::new("noisy", "pictures/gone.png")],
        note: String::new(),
    });
    let err = r.write(dir.path()).unwrap_err().to_string();
    assert!(err.contains("gone.png"), "{err}");
}

/// The plots explain themselves: a title, axis titles with units, log axes said to be log, a legend of the
/// methods that have points, each in its color.
#[test]
fn plots_have_titles_units_and_a_legend_in_the_figure() {
    let r = report();
    let methods = ["noisy", "hush|unet"];
    let svg = hush_eval::plot_error_vs_time(&r.rows, &methods, hush_eval::tradeoff::ErrorMetric::RelMse, 400, 300);
    assert!(svg.contains("viewBox=\"0 0 400 300\""), "{svg}");
    assert_eq!(hush_plot::texts(&svg, "title"), ["relMSE against time, a line per view (2)"]);
    assert_eq!(hush_plot::texts(&svg, "x-title"), ["render + denoise time (s) (log scale)"]);
    assert_eq!(hush_plot::texts(&svg, "y-title"), ["relMSE (linear HDR, unitless) (log scale)"]);
    assert_eq!(hush_plot::texts(&svg, "legend"), ["noisy", "hush|unet"]);
    assert!(svg.contains(&hush_plot::hex(hush_eval::series_color(1))), "the denoiser's color");
}

/// A figure's kind and its images' methods and marks survive `summary.json`; a schema-2 figure has none.
#[test]
fn figure_kinds_round_trip_and_old_figures_have_none() {
    let mut r = report();
    let marks = hush_eval::pictures::Marks { over_low: 0.25, over_high: 0.125 };
    let image = FigureImage { method: Some("noisy".into()), marks: Some(marks), ..FigureImage::new("noisy", "p.png") };
    let kind = FigureKind::Differences { view: "v".into(), spp: 4 };
    r.figures.push(Figure { title: "v at 4 spp".into(), kind, images: vec![image], note: String::new() });
    let json = r.to_json();
    assert!(json.contains("\"type\": \"differences\""), "{json}");
    let back: Report = serde_json::from_str(&json).unwrap();
    assert_eq!(back.figures, r.figures);
    let old: Figure = serde_json::from_str(r#"{"title": "t", "images": [{"caption": "c", "path": "p"}]}"#).unwrap();
    assert_eq!((old.kind, old.images[0].method.clone(), old.images[0].marks), (FigureKind::Other, None, None));
}
