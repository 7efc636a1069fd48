//! The HTML report: escaping, inlining, and (ignored by default, run by `cargo xtask eval --check-html`)
//! rendering in headless Chromium.

use std::path::Path;
use std::process::Command;

use hush_eval::html::{base64, escape_html};
use hush_eval::{Figure, FigureImage, FigureKind, Report, Row};

use crate::TempDir;

#[test]
fn base64_matches_rfc_4648() {
    let cases = [
        ("", ""),
        ("f", "Zg=="),
        ("fo", "Zm8="),
        ("foo", "Zm9v"),
        ("foob", "Zm9vYg=="),
        ("fooba", "Zm9vYmE="),
        ("foobar", "Zm9vYmFy"),
    ];
    for (plain, encoded) in cases {
        assert_eq!(base64(plain.as_bytes()), encoded, "{plain:?}");
    }
    assert_eq!(base64(&[0xfb, 0xff]), "+/8=");
}

#[test]
fn escape_html_escapes_markup_and_quotes() {
    assert_eq!(escape_html(r#"<a href="x">&'</a>"#), "&lt;a href=&quot;x&quot;&gt;&amp;&#39;&lt;/a&gt;");
}

/// A report whose names try to inject markup, with a figure: written, it must be one file with every image
/// inline and the names escaped.
fn hostile_report(dir: &Path) -> Report {
    let mut r = crate::report::report();
    for row in &mut r.rows {
        if row.method == "hush|unet" {
            row.method = "<script>alert(1)</script>".into();
        }
    }
    r.notes.push("a & b <b>bold</b>".into());
    let png = hush_eval::pictures::Rgb8 { width: 2, height: 1, data: vec![255, 0, 0, 0, 0, 255] }.to_png().unwrap();
    std::fs::create_dir_all(dir.join("pictures")).unwrap();
    std::fs::write(dir.join("pictures/x.png"), png).unwrap();
    r.figures.push(Figure {
        kind: FigureKind::Other,
        title: "crops \"quoted\"".into(),
        images: vec![FigureImage::new("noisy <i>", "pictures/x.png")],
        note: "note".into(),
    });
    r
}

#[test]
fn html_is_self_contained_and_escaped() {
    let dir = TempDir::new("html");
    let r = hostile_report(dir.path());
    r.write(dir.path()).unwrap();
    let html = std::fs::read_to_string(dir.path().join("report.html")).unwrap();
    assert!(!html.contains("<script") && html.contains("&lt;script&gt;alert(1)&lt;/script&gt;"), "{html}");
    assert!(html.contains("a &amp; b &lt;b&gt;bold&lt;/b&gt;") && html.contains("noisy &lt;i&gt;"));
    assert!(!html.contains("http:") && !html.contains("https:") && !html.contains("<link"), "no external resource");
    let images = html.matches("<img ").count();
    assert_eq!(images, 3, "two plots and one picture");
    assert_eq!(html.matches("src=\"data:image/png;base64,").count(), images, "every image inline");
    assert!(html.contains("as the thesis&#39;s Tables 8.1–8.3") && html.contains("Error against run time"));
    let _: Row = r.rows[0].clone();
}

const INSTALL: &str = "apt-get install -y chromium";

/// Renders report.html in headless Chromium: the page must load without console or network errors, its DOM
/// must hold the report, and the screenshot must not be blank. Heavy (starts a browser) and needs Chromium,
/// so it is ignored by default: `cargo xtask eval --check-html` runs it (`--ignored`);
/// `HUSH_CHROMIUM_HTML=<file>` checks that report instead of a synthetic one.
#[test]
#[ignore = "starts headless Chromium: run by `cargo xtask eval --check-html`"]
fn html_renders_in_chromium() {
    let chromium = ["chromium", "chromium-browser", "google-chrome"]
        .into_iter()
        .find(|c| Command::new(c).arg("--version").output().is_ok_and(|o| o.status.success()))
        .unwrap_or_else(|| panic!("Chromium is not installed: install it with `{INSTALL}` (Debian/Ubuntu, as root)"));
    let dir = TempDir::new("chromium");
    let html = match std::env::var_os("HUSH_CHROMIUM_HTML") {
        Some(path) => std::path::PathBuf::from(path).canonicalize().expect("HUSH_CHROMIUM_HTML names a file"),
        None => {
            let out = dir.path().join("report");
            hostile_report(&out).write(&out).unwrap();
            out.join("report.html")
        }
    };
    let url = format!("file://{}", html.display());
    let run = |extra: &[&str]| {
        let profile = tempfile_dir(dir.path(), extra.len());
        let out = Command::new(chromium)
            .args(["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run"])
            .args(["--disable-background-networking", "--disable-component-update", "--disable-sync"])
            .arg(format!("--user-data-dir={}", profile.display()))
            .args(["--enable-logging=stderr", "--v=0", "--window-size=1200,2000"])
            .args(extra)
            .arg(&url)
            .output()
            .expect("chromium starts");
        assert!(out.status.success(), "chromium failed: {}", String::from_utf8_lossy(&out.stderr));
        out
    };
    let screenshot = dir.path().join("report.png");
    let shot = run(&[&format!("--screenshot={}", screenshot.display())]);
    let dom = run(&["--dump-dom"]);
    for out in [&shot, &dom] {
        let log = String::from_utf8_lossy(&out.stderr);
        let errors: Vec<&str> = log
            .lines()
            .filter(|l| l.contains(":CONSOLE") || l.contains("net::ERR_") || l.contains("Uncaught"))
            .collect();
        assert!(errors.is_empty(), "{} logged errors:\n{}", html.display(), errors.join("\n"));
    }
    let dom = String::from_utf8_lossy(&dom.stdout);
    assert!(dom.contains("Denoising evaluation") && dom.contains("Error against run time"), "{dom}");
    assert!(dom.matches("<img").count() >= 2, "the plots are in the DOM");
    // Chromium does not log a missing local file: the page must not refer to any.
    for (i, _) in dom.match_indices(" src=\"") {
        assert!(
            dom[i + 6..].starts_with("data:"),
            "{} loads a file: {}",
            html.display(),
            &dom[i..(i + 80).min(dom.len())]
        );
    }
    assert!(!dom.contains("<script"), "the report has no scripts");

    let picture = image::open(&screenshot).unwrap_or_else(|e| panic!("{}: {e}", screenshot.display())).to_rgb8();
    let non_white = picture.pixels().filter(|p| p.0.iter().any(|&c| c < 200)).count();
    let fraction = non_white as f64 / (picture.width() * picture.height()) as f64;
    // Text and tables alone cover a few per cent of a 1200×2000 page; a blank page covers none.
    assert!(fraction > 0.01, "the screenshot {} is (almost) blank: {fraction}", screenshot.display());
    eprintln!(
        "chromium rendered {} ({:.1} % non-white); screenshot kept at {}",
        html.display(),
        100.0 * fraction,
        keep(&screenshot).display()
    );
}

/// A fresh profile directory for one browser run.
fn tempfile_dir(base: &Path, n: usize) -> std::path::PathBuf {
    let dir = base.join(format!("profile-{n}"));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Copies the screenshot next to the checked report's target folder so it outlives the test's temp dir.
fn keep(screenshot: &Path) -> std::path::PathBuf {
    let to = std::env::temp_dir().join("hush-eval-report-screenshot.png");
    std::fs::copy(screenshot, &to).map(|_| to).unwrap_or_else(|_| screenshot.to_path_buf())
}
