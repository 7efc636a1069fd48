//! `report.html`: the report as one self-contained page. Plots are inline SVG, pictures (crops, difference
//! pictures) base64 `data:` URIs, the image comparison's HDR data base64 in the page with its script
//! ([`crate::viewer`]); there are no external scripts, style sheets or links to load. All text goes through
//! [`escape_html`].

use std::fmt::Write as _;
use std::path::Path;

use crate::doc::{Block, Document, Grid, Inline, Text};
use crate::report::{CONVENTIONS, TRADEOFF_INTRO};
use crate::tradeoff::ErrorMetric;
use crate::{Error, Report, Result};

const STYLE: &str = "body{font-family:sans-serif;max-width:1150px;margin:1em auto;padding:0 1em;color:#222}\
table{border-collapse:collapse;margin:0.5em 0 1.5em}td,th{border:1px solid #ccc;padding:2px 6px}\
td.n{text-align:right;font-variant-numeric:tabular-nums}th{background:#f2f2f2}\
figure{display:inline-block;margin:4px;text-align:center}ul.headline{font-size:105%}.plot svg{max-width:100%;height:auto}img{image-rendering:pixelated;max-width:100%}\
.swatch{display:inline-block;width:1.2em;height:0.8em;vertical-align:middle}p.small{font-size:90%;color:#555}";

/// Escapes `&`, `<`, `>`, `"` and `'` for HTML text and attribute values (the same rules as the SVG of
/// [`hush_plot`], which the page inlines).
pub fn escape_html(s: &str) -> String {
    hush_plot::xml(s)
}

/// Standard base64 (RFC 4648, with padding).
pub fn base64(bytes: &[u8]) -> String {
    const ALPHABET: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::with_capacity(bytes.len().div_ceil(3) * 4);
    for chunk in bytes.chunks(3) {
        let b = [chunk[0], *chunk.get(1).unwrap_or(&0), *chunk.get(2).unwrap_or(&0)];
        let n = (u32::from(b[0]) << 16) | (u32::from(b[1]) << 8) | u32::from(b[2]);
        for i in 0..4 {
            if i <= chunk.len() {
                out.push(ALPHABET[((n >> (18 - 6 * i)) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

/// An image file of the report directory, inline: an SVG as its markup (its text stays text), anything else
/// (PNG) as an `<img>` with a data URI.
fn img(dir: &Path, path: &str, alt: &str) -> Result<String> {
    let file = dir.join(path);
    let read_error = |source| Error::File { path: file.clone(), action: "read for report.html", source };
    if path.ends_with(".svg") {
        let svg = std::fs::read_to_string(&file).map_err(read_error)?;
        // Inline SVG needs no namespace declaration (and the page then names no address at all).
        let svg = svg.replacen(" xmlns=\"http://www.w3.org/2000/svg\"", "", 1);
        return Ok(format!(
            "<span class=\"plot\" role=\"img\" aria-label=\"{}\">{}</span>",
            escape_html(alt),
            svg.trim_end()
        ));
    }
    let bytes = std::fs::read(&file).map_err(read_error)?;
    Ok(format!("<img alt=\"{}\" src=\"data:image/png;base64,{}\">", escape_html(alt), base64(&bytes)))
}

/// The start of a page, up to and including `<body>`.
fn head(title: &str) -> String {
    format!(
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>{}</title>\
         <style>{STYLE}{}</style></head><body>\n",
        escape_html(title),
        crate::viewer::STYLE
    )
}

/// The report as HTML; images named by the report are read from `dir` and inlined. In order: what was
/// compared and the headline, the image comparison of each view, the thesis-style tables, the plots of
/// error against time, the crops and difference pictures, then (collapsed) the conventions, notes, skipped
/// methods, every row and every comparison.
pub fn to_html(report: &Report, dir: &Path) -> Result<String> {
    let mut h = head("Denoising evaluation");
    let _ = writeln!(h, "<h1>Denoising evaluation</h1>\n<p>{}</p>", escape_html(&report.compared()));
    let headlines = report.headlines();
    if !headlines.is_empty() {
        h.push_str("<ul class=\"headline\">");
        for line in &headlines {
            let _ = write!(h, "<li><b>{}</b></li>", escape_html(line));
        }
        h.push_str("</ul>\n");
    }
    if !report.skipped.is_empty() {
        let names: Vec<String> = report.skipped.iter().map(|s| escape_html(&s.method)).collect();
        let _ = writeln!(
            h,
            "<p class=\"small\">Not run: {} (why and how to install: under Details).</p>",
            names.join(", ")
        );
    }
    if !report.viewers.is_empty() {
        h.push_str("<h2>The images</h2>\n");
        for (i, viewer) in report.viewers.iter().enumerate() {
            h.push_str(&crate::viewer::to_html(report, viewer, dir, i)?);
        }
    }
    for (title, t) in report.thesis_tables() {
        let _ = writeln!(h, "<h2>{}</h2>", escape_html(&title));
        grid(&mut h, &Grid::of_table(&t), dir)?;
    }
    let _ = writeln!(h, "<h2>Error against run time</h2>\n<p>{}</p>", escape_html(TRADEOFF_INTRO));
    for metric in ErrorMetric::ALL {
        let alt = format!("{} against seconds", metric.label());
        let _ = writeln!(h, "<figure>{}</figure>", img(dir, &Report::plot_file(metric), &alt)?);
    }
    if let Some(t) = report.overview_table() {
        h.push_str("<p>Over the views:</p>");
        grid(&mut h, &Grid::of_table(&t), dir)?;
    }
    for figure in &report.figures {
        let _ = write!(h, "<h2>{}</h2>\n<div>", escape_html(&figure.title));
        for image in &figure.images {
            let _ = write!(
                h,
                "<figure>{}<figcaption>{}</figcaption></figure>",
                img(dir, &image.path, &image.caption)?,
                escape_html(&image.caption)
            );
        }
        h.push_str("</div>\n");
        if !figure.note.is_empty() {
            let _ = writeln!(h, "<p class=\"small\">{}</p>", escape_html(&figure.note));
        }
    }
    h.push_str(
        "<details><summary><h2 style=\"display:inline\">Details: conventions, notes, every row</h2></summary>\n",
    );
    let _ = writeln!(h, "<h3>Conventions</h3><p class=\"small\">{}</p>", escape_html(CONVENTIONS));
    if !report.notes.is_empty() {
        h.push_str("<h3>Notes</h3><ul>");
        for n in &report.notes {
            let _ = write!(h, "<li>{}</li>", escape_html(n));
        }
        h.push_str("</ul>\n");
    }
    if !report.skipped.is_empty() {
        h.push_str("<h3>Skipped methods</h3><ul>");
        for s in &report.skipped {
            let install =
                s.install.as_deref().map(|c| format!(" Install: <code>{}</code>", escape_html(c))).unwrap_or_default();
            let _ = write!(h, "<li>{}: skipped: {}.{install}</li>", escape_html(&s.method), escape_html(&s.reason));
        }
        h.push_str("</ul>\n");
    }
    for (title, t) in report.detail_tables() {
        let _ = writeln!(h, "<h3>{}</h3>", escape_html(&title));
        grid(&mut h, &Grid::of_table(&t), dir)?;
    }
    let comparisons = report.tradeoff();
    if !comparisons.is_empty() {
        h.push_str("<h3>Error against run time, per view</h3><ul>");
        for c in comparisons {
            let _ = write!(h, "<li>{}</li>", escape_html(&c.sentence()));
        }
        h.push_str("</ul>\n");
    }
    h.push_str("</details>\n");
    if !report.viewers.is_empty() {
        let _ = writeln!(h, "<script>{}</script>", crate::viewer::SCRIPT);
    }
    h.push_str("</body></html>\n");
    Ok(h)
}

/// A [`Document`] as one page; its images are read from `dir` and inlined, so a missing one is an error
/// naming it.
pub fn document_to_html(doc: &Document, dir: &Path) -> Result<String> {
    let mut h = head(&doc.title);
    for block in &doc.blocks {
        match block {
            Block::Heading(level, t) => {
                let level = level.clamp(&1, &6);
                let _ = writeln!(h, "<h{level}>{}</h{level}>", inline_html(t, dir)?);
            }
            Block::Paragraph(t) => {
                let _ = writeln!(h, "<p>{}</p>", inline_html(t, dir)?);
            }
            Block::List(items) => {
                h.push_str("<ul>\n");
                for item in items {
                    let _ = writeln!(h, "<li>{}</li>", inline_html(item, dir)?);
                }
                h.push_str("</ul>\n");
            }
            Block::Table(g) => grid(&mut h, g, dir)?,
        }
    }
    h.push_str("</body></html>\n");
    Ok(h)
}

/// A table; right-aligned columns get class `n` (numbers). A [`crate::Table`]'s links are left out (see
/// [`Grid::of_table`]): the page loads nothing.
fn grid(h: &mut String, g: &Grid, dir: &Path) -> Result<()> {
    h.push_str("<table>\n<tr>");
    for head in &g.header {
        let _ = write!(h, "<th>{}</th>", escape_html(head));
    }
    h.push_str("</tr>\n");
    for row in &g.rows {
        h.push_str("<tr>");
        for (i, cell) in row.iter().enumerate() {
            let class = if g.right.get(i).copied().unwrap_or(false) { " class=n" } else { "" };
            let _ = write!(h, "<td{class}>{}</td>", inline_html(cell, dir)?);
        }
        h.push_str("</tr>\n");
    }
    h.push_str("</table>\n");
    Ok(())
}

fn inline_html(t: &Text, dir: &Path) -> Result<String> {
    let mut h = String::new();
    for i in t {
        match i {
            Inline::Text(s) => h.push_str(&escape_html(s)),
            Inline::Code(s) => {
                let _ = write!(h, "<code>{}</code>", escape_html(s));
            }
            Inline::Bold(s) => {
                let _ = write!(h, "<b>{}</b>", escape_html(s));
            }
            Inline::Image { alt, path } => h.push_str(&img(dir, path, alt)?),
            Inline::Link { text, href } => {
                let href = match href.strip_suffix("report.md") {
                    Some(stem) => format!("{stem}report.html"),
                    None => href.clone(),
                };
                let _ = write!(h, "<a href=\"{}\">{}</a>", escape_html(&href), escape_html(text));
            }
        }
    }
    Ok(h)
}
