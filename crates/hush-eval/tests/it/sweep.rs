//! The sweep reports: reading what runs left, the report of a sweep, the document writer and the loss plot.

use std::path::{Path, PathBuf};

use hush_eval::doc::{Block, Document, Grid, Inline, image, text};
use hush_eval::pictures::{Marks, Rgb8};
use hush_eval::sweep::claims::Verdict;
use hush_eval::sweep::results::{EvalRow, Picture, RunResult, parse_eval, parse_pictures};
use hush_eval::sweep::{Plan, PlanRun, PlanScale, PlanSweep, read_plan, report, write_reports};
use hush_eval::{FigureImage, FigureKind};
use hush_train::{EpochRow, parse_metrics_csv};

use crate::TempDir;

/// A run of sweep `x` named `name`, in `dir`.
pub fn run(sweep: &str, name: &str, dir: &Path) -> PlanRun {
    PlanRun { sweep: sweep.into(), name: name.into(), group: name.into(), dir: dir.to_path_buf(), ..PlanRun::default() }
}

fn result(run: PlanRun, epochs: Vec<EpochRow>, eval: Vec<EvalRow>, pictures: Vec<Picture>) -> RunResult {
    RunResult { run, done: true, epochs, eval, pictures }
}

/// A row of `metrics.csv` with what the sweep reads of it.
pub fn epoch(epoch: usize, train_loss: f64, test_loss: Option<f64>, seconds: f64) -> EpochRow {
    EpochRow { epoch, step: 2 * epoch, train_loss, test_loss, lr: 1e-3, seconds, loader_share: 0.0, best: false }
}

fn png(path: &Path) {
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    std::fs::write(path, Rgb8 { width: 1, height: 1, data: vec![9, 9, 9] }.to_png().unwrap()).unwrap();
}

#[test]
fn metrics_csv_with_gaps_and_a_resume() {
    let csv = "epoch,step,train_loss,test_loss,lr,seconds,loader_share,best\n\
               1,2,0.5,0.6,0.001,10,0.1,true\n2,4,0.4,,0.001,20,0.1,false\n\
               3,6,0.3,0.7,0.001,5,0.1,false\nbroken\n";
    let r = result(run("x", "base", Path::new("x")), parse_metrics_csv(csv), Vec::new(), Vec::new());
    assert_eq!(r.epochs.len(), 3);
    assert_eq!(r.epochs[1].test_loss, None);
    // 10 + 10 + 5 (the clock restarted at the resume) over 3 epochs.
    assert!((r.seconds_per_epoch().unwrap() - 25.0 / 3.0).abs() < 1e-12);
    assert_eq!(r.best(), Some((1, 0.6)));
    assert_eq!(r.last_tested(), Some((3, 0.3, 0.7)));
    // Columns are found by name, in any order.
    let moved = parse_metrics_csv("seconds,lr,train_loss,step,epoch\n4,0.001,0.25,14,7\n");
    assert_eq!(moved, [epoch(7, 0.25, None, 4.0)]);
}

#[test]
fn eval_rows_of_both_schemas() {
    let file = Path::new("eval/summary.json");
    let v1 = serde_json::json!({"rows": [
        {"view": "v", "method": "noisy", "spp": 4, "psnr": 20.0, "ssim": 0.5, "seconds": 1.5, "preview": "p/n.png"},
        {"view": "v", "method": "train/model", "spp": 4, "psnr": 30.0, "seconds": 0.2},
    ]});
    let rows = parse_eval(&v1.to_string(), file).unwrap();
    assert_eq!(rows[0].render_seconds, Some(1.5));
    assert_eq!(rows[0].denoise_seconds, None);
    assert_eq!(rows[0].preview.as_deref(), Some("p/n.png"));
    assert_eq!(rows[1].denoise_seconds, Some(0.2));
    assert_eq!(rows[1].ssim, None);
    let v2 = serde_json::json!({"schema": 2, "rows": [
        {"view": "v", "method": "train/model", "spp": 4, "psnr": 30.0, "render_seconds": 1.5,
         "denoise_seconds": 0.3, "ms_ssim": 0.9},
        {"view": "v", "method": "oidn", "spp": 4, "psnr": 33.0, "denoise_seconds": 0.1},
    ]});
    let rows = parse_eval(&v2.to_string(), file).unwrap();
    assert_eq!((rows[0].render_seconds, rows[0].denoise_seconds), (Some(1.5), Some(0.3)));
    let r = result(run("x", "base", Path::new("x")), Vec::new(), rows, vec![]);
    assert_eq!(r.model_rows().len(), 1);
    assert_eq!(r.model_rows()[0].method, "train/model");
    // A summary that is not one names its file.
    let err = parse_eval("{\"rows\": 3}", file).unwrap_err().to_string();
    assert!(err.contains("eval/summary.json"), "{err}");
}

/// The crops and difference pictures of `hush eval`'s figures, found by their kind, view, spp and method.
#[test]
fn pictures_of_the_figures() {
    let crops = |spp| serde_json::json!({"type": "crops", "view": "v", "spp": spp});
    let summary = serde_json::json!({"schema": 3, "rows": [], "figures": [
        {"title": "v at 4 spp: crops", "kind": crops(4), "images": [
            {"caption": "noisy", "path": "pictures/v_000004_noisy_crop.png", "method": "noisy"},
            {"caption": "train/model", "path": "pictures/v_000004_train-model_crop.png", "method": "train/model"},
            {"caption": "reference", "path": "pictures/v_000004_reference_crop.png", "method": "reference"}]},
        {"title": "anything", "kind": {"type": "differences", "view": "v", "spp": 4}, "images": [
            {"caption": "noisy: 40.0 % > 3 %, 9.0 % > 10 %", "path": "pictures/v_000004_noisy_diff.png",
             "method": "noisy", "marks": {"over_low": 0.4, "over_high": 0.09}},
            {"caption": "whatever", "path": "pictures/v_model_diff.png",
             "method": "train/model", "marks": {"over_low": 0.125, "over_high": 0.01}}]},
        {"title": "v at 16 spp: crops", "kind": crops(16),
         "images": [{"caption": "train/model", "path": "pictures/16.png", "method": "train/model"}]},
        {"title": "v at 4 spp: crops", "images": [{"caption": "train/model", "path": "old.png"}]},
    ]});
    let pictures = parse_pictures(&summary.to_string(), Path::new("summary.json")).unwrap();
    let r = result(run("x", "base", Path::new("x")), Vec::new(), Vec::new(), pictures);
    assert_eq!(r.pictures.len(), 7);
    assert_eq!(r.pictures[6].kind, FigureKind::Other, "a figure of a schema-2 summary has no kind");
    assert_eq!(r.crop("v", 4, "train/model"), Some("pictures/v_000004_train-model_crop.png"));
    assert_eq!(r.crop("v", 16, "train/model"), Some("pictures/16.png"));
    assert_eq!(r.crop("v", 4, "reference"), Some("pictures/v_000004_reference_crop.png"));
    assert_eq!(r.crop("w", 4, "train/model"), None);
    assert_eq!(
        r.difference("v", 4, "train/model"),
        Some(("pictures/v_model_diff.png", "12.5 % > 3 %, 1.0 % > 10 %".to_string()))
    );
    assert_eq!(r.difference("v", 16, "train/model"), None);
}

fn tiny() -> PlanScale {
    PlanScale { name: "tiny".into(), scenes: vec!["a".into()], seeds: vec![0], ..PlanScale::default() }
}

#[test]
fn a_report_with_a_missing_run() {
    let tmp = TempDir::new("sweep-report");
    let dir = tmp.path().to_path_buf();
    let sweep = PlanSweep { name: "architecture".into(), description: String::new(), dir: dir.clone(), runs: vec![] };
    let row = |method: &str, psnr| EvalRow {
        view: "v".into(),
        method: method.into(),
        spp: 4,
        psnr: Some(psnr),
        ssim: Some(0.5),
        render_seconds: Some(2.0),
        denoise_seconds: (method != "noisy").then_some(0.5),
        preview: Some(format!("previews/{method}.png")),
        ..EvalRow::default()
    };
    let picture = |kind: &str, method: &str, path: &str, marks: Option<(f64, f64)>| {
        let kind = match kind {
            "crops" => FigureKind::Crops { view: "v".into(), spp: 4 },
            _ => FigureKind::Differences { view: "v".into(), spp: 4 },
        };
        let marks = marks.map(|(over_low, over_high)| Marks { over_low, over_high });
        let image = FigureImage { method: Some(method.into()), marks, ..FigureImage::new(method, path) };
        png(&dir.join("oidn/eval").join(path));
        Picture { kind, image }
    };
    for p in ["previews/noisy.png", "previews/train/model.png"] {
        png(&dir.join("oidn/eval").join(p));
    }
    let mut dae = result(run("architecture", "dae", &dir.join("dae")), vec![], vec![], vec![]);
    dae.done = false;
    dae.run.train = vec![("arch".into(), "autoencoder".into())];
    let results = vec![
        result(
            run("architecture", "oidn", &dir.join("oidn")),
            vec![epoch(1, 0.5, Some(0.6), 3.0)],
            vec![row("noisy", 20.0), row("train/model", 25.0)],
            vec![
                picture("crops", "reference", "r.png", None),
                picture("crops", "noisy", "n.png", None),
                picture("crops", "train/model", "m.png", None),
                picture("differences", "noisy", "nd.png", Some((0.4, 0.09))),
                picture("differences", "train/model", "md.png", Some((0.125, 0.01))),
            ],
        ),
        dae,
    ];
    let claims = report::write(&sweep, &tiny(), &results, &dir).unwrap();
    let md = std::fs::read_to_string(dir.join("report.md")).unwrap();
    assert!(md.contains("1 of 2 runs complete"), "{md}");
    assert!(md.contains("Not complete: dae."));
    assert!(md.contains("| oidn | `` | 1 | 3.00 | 0.5000 | 0.6000 | 0.6000 (1) | 0.1000 | 25.00 | 0.5000 |"), "{md}");
    assert!(md.contains("| 4 | oidn | 2.00 | 0.500 | 2.50 | 25.00 |"), "{md}");
    assert!(md.contains("| 4 | noisy | 2.00 | – | 2.00 | 20.00 |"), "{md}");
    assert!(dir.join("error_vs_time_rel_mse.svg").is_file() && dir.join("error_vs_time.csv").is_file());
    assert!(md.contains("](error_vs_time_one_minus_ssim.svg)"), "{md}");
    assert!(md.contains("| noisy | 20.00 / 0.5000 |"));
    assert!(
        md.contains("| ![noisy](oidn/eval/previews/noisy.png) | ![oidn](oidn/eval/previews/train/model.png) |"),
        "{md}"
    );
    assert!(md.contains("## Crops and differences"), "{md}");
    assert!(md.contains("| reference | ![reference](oidn/eval/r.png) | – | – |"), "{md}");
    assert!(
        md.contains("| noisy | ![noisy](oidn/eval/n.png) | ![noisy: pixels off](oidn/eval/nd.png) | 40.0 %"),
        "{md}"
    );
    assert!(
        md.contains(
            "| oidn | ![oidn](oidn/eval/m.png) | ![oidn: pixels off](oidn/eval/md.png) | 12.5 % > 3 %, 1.0 % > 10 % |"
        ),
        "{md}"
    );
    assert_eq!(claims[0].verdict, Verdict::NotMeasured);
    assert!(md.contains("not measured"));
    assert!(dir.join("curves.csv").is_file());
    let loss = std::fs::read_to_string(dir.join("test_loss.svg")).unwrap();
    assert_eq!(hush_plot::texts(&loss, "title"), ["The test loss of each run"]);
    assert_eq!(hush_plot::texts(&loss, "x-title"), ["epoch"]);
    let page = std::fs::read_to_string(dir.join("report.html")).unwrap();
    assert!(page.contains("<h1>Sweep <code>architecture</code> at scale <code>tiny</code></h1>"), "{page}");
    assert!(page.contains("<th>run</th><th>other flags</th>"));
    assert!(page.contains("<td><img alt=\"oidn\" src=\"data:image/png;base64,"), "{page}");
    assert!(!page.contains("|---"));
    assert_eq!(page.matches("<img ").count(), page.matches("src=\"data:image/png;base64,").count(), "all inline");
    assert!(page.contains("<text class=\"title\"") && !page.contains("http:"), "the plots inline, as SVG");
}

#[test]
fn a_document_as_markdown_and_html() {
    let tmp = TempDir::new("sweep-doc");
    png(&tmp.path().join("q.png"));
    let mut table = Grid::new(vec!["h".into(), "i".into()], vec![false, true]);
    table.rows.push(vec![vec![Inline::Bold("r".into())], text("1 < 2 | 3")]);
    let mut para = text("text ");
    para.extend(image("p", "q.png"));
    let doc = Document {
        title: "t".into(),
        blocks: vec![
            Block::Heading(1, vec![Inline::Text("T ".into()), Inline::Code("x".into())]),
            Block::List(vec![vec![Inline::Link { text: "a".into(), href: "a/report.md".into() }]]),
            Block::Table(table),
            Block::Paragraph(para),
        ],
    };
    let md = doc.to_markdown();
    assert!(md.contains("# T `x`\n\n- [a](a/report.md)\n\n| h | i |\n|---|--:|\n| **r** | 1 < 2 \\| 3 |\n"), "{md}");
    assert!(md.contains("text ![p](q.png)"), "{md}");
    let page = hush_eval::html::document_to_html(&doc, tmp.path()).unwrap();
    for want in [
        "<h1>T <code>x</code></h1>",
        "<ul>\n<li><a href=\"a/report.html\">a</a></li>\n</ul>",
        "<table>\n<tr><th>h</th><th>i</th></tr>\n<tr><td><b>r</b></td><td class=n>1 &lt; 2 | 3</td></tr>\n</table>",
        "<p>text <img alt=\"p\" src=\"data:image/png;base64,",
    ] {
        assert!(page.contains(want), "missing {want:?} in {page}");
    }
    let missing = Document { blocks: vec![Block::Paragraph(image("gone", "gone.png"))], ..doc };
    let err = hush_eval::html::document_to_html(&missing, tmp.path()).unwrap_err().to_string();
    assert!(err.contains("gone.png"), "{err}");
}

/// A plan read from JSON: runs' reports and the `all` report; the links of `all` go to the sweeps' reports.
#[test]
fn a_plan_writes_every_report() {
    let tmp = TempDir::new("sweep-plan");
    let root: PathBuf = tmp.path().to_path_buf();
    let sweep = |name: &str| PlanSweep {
        name: name.into(),
        description: format!("the {name} sweep"),
        dir: root.join(name).join("tiny"),
        runs: vec![run(name, "base", &root.join(name).join("tiny/base"))],
    };
    let plan = Plan { scale: tiny(), sweeps: vec![sweep("loss"), sweep("epochs")], all: Some(root.join("all/tiny")) };
    let file = root.join("plan.json");
    std::fs::write(&file, serde_json::to_string(&plan).unwrap()).unwrap();
    let read = read_plan(&file).unwrap();
    assert_eq!(read, plan);
    let written = write_reports(&read).unwrap();
    assert_eq!(written.len(), 3);
    assert!(written.iter().all(|f| f.is_file() && f.with_file_name("report.html").is_file()), "{written:?}");
    let all = std::fs::read_to_string(root.join("all/tiny/report.md")).unwrap();
    assert!(all.contains("- [loss](../../loss/tiny/report.md)"), "{all}");
    assert!(!all.contains("## Error against run time"), "no run is complete: {all}");
    std::fs::write(&file, "{\"sweeps\": []}").unwrap();
    let err = read_plan(&file).unwrap_err().to_string();
    assert!(err.contains("plan.json") && err.contains("scale"), "{err}");
}
