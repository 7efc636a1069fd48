//! `report.html`: the report as one self-contained page. Every image (plots, crops, difference pictures) is
//! inlined as a base64 `data:` URI; there are no scripts, no external style sheets and no links to load.
//! All text goes through [`escape_html`].

use std::fmt::Write as _;
use std::path::Path;

use crate::doc::{Block, Document, Grid, Inline, Text};
use crate::report::{CONVENTIONS, REFERENCE, TRADEOFF_INTRO};
use crate::tradeoff::ErrorMetric;
use crate::{Error, Report, Result};

const STYLE: &str = "body{font-family:sans-serif;max-width:1150px;margin:1em auto;padding:0 1em;color:#222}\
table{border-collapse:collapse;margin:0.5em 0 1.5em}td,th{border:1px solid #ccc;padding:2px 6px}\
td.n{text-align:right;font-variant-numeric:tabular-nums}th{background:#f2f2f2}\
figure{display:inline-block;margin:4px;text-align:center}img{image-rendering:pixelated;max-width:100%}\
.swatch{display:inline-block;width:1.2em;height:0.8em;vertical-align:middle}p.small{font-size:90%;color:#555}";

/// Escapes `&`, `<`, `>`, `"` and `'` for HTML text and attribute values.
pub fn escape_html(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            c => out.push(c),
        }
    }
    out
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

/// A PNG file of the report directory as an `<img>` with a data URI.
fn img(dir: &Path, path: &str, alt: &str) -> Result<String> {
    let file = dir.join(path);
    let bytes = std::fs::read(&file).map_err(|source| Error::File {
        path: file.clone(),
        action: "read for report.html",
        source,
    })?;
    Ok(format!("<img alt=\"{}\" src=\"data:image/png;base64,{}\">", escape_html(alt), base64(&bytes)))
}

/// The start of a page, up to and including `<body>`.
fn head(title: &str) -> String {
    format!(
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>{}</title>\
         <style>{STYLE}</style></head><body>\n",
        escape_html(title)
    )
}

/// The report as HTML; images named by the report are read from `dir` and inlined.
pub fn to_html(report: &Report, dir: &Path) -> Result<String> {
    let mut h = head("Denoising evaluation");
    let _ = write!(h, "<h1>Denoising evaluation</h1>\n<p class=\"small\">{}</p>\n", escape_html(CONVENTIONS));
    if !report.notes.is_empty() {
        h.push_str("<ul>");
        for n in &report.notes {
            let _ = write!(h, "<li>{}</li>", escape_html(n));
        }
        h.push_str("</ul>\n");
    }
    if !report.skipped.is_empty() {
        h.push_str("<h2>Skipped methods</h2><ul>");
        for s in &report.skipped {
            let install =
                s.install.as_deref().map(|c| format!(" Install: <code>{}</code>", escape_html(c))).unwrap_or_default();
            let _ = write!(h, "<li>{}: skipped: {}.{install}</li>", escape_html(&s.method), escape_html(&s.reason));
        }
        h.push_str("</ul>\n");
    }
    for (title, t) in report.tables() {
        let _ = writeln!(h, "<h2>{}</h2>", escape_html(&title));
        grid(&mut h, &Grid::of_table(&t), dir)?;
    }
    let _ = writeln!(h, "<h2>Error against run time</h2>\n<p>{}</p>", escape_html(TRADEOFF_INTRO));
    let methods: Vec<&str> = report.methods().into_iter().filter(|m| *m != REFERENCE).collect();
    for metric in ErrorMetric::ALL {
        let caption = match crate::plot::decades(&report.rows, &methods, metric) {
            Some((x0, x1, y0, y1)) => format!(
                "{} against seconds: x from 1e{x0} to 1e{x1} s, y from 1e{y0} to 1e{y1}, log-log",
                metric.label()
            ),
            None => format!("{} against seconds: no point to plot", metric.label()),
        };
        let _ = writeln!(
            h,
            "<figure>{}<figcaption>{}</figcaption></figure>",
            img(dir, &Report::plot_file(metric), &caption)?,
            escape_html(&caption)
        );
    }
    h.push_str("<table><tr><th>color</th><th>method</th></tr>");
    for (i, m) in methods.iter().enumerate() {
        let (r, g, b) = crate::plot::series_color(i);
        let _ = write!(
            h,
            "<tr><td><span class=swatch style=\"background:#{r:02x}{g:02x}{b:02x}\"></span></td><td>{}</td></tr>",
            escape_html(m)
        );
    }
    h.push_str("</table>\n");
    if let Some(t) = report.overview_table() {
        h.push_str("<p>Over the views:</p>");
        grid(&mut h, &Grid::of_table(&t), dir)?;
        h.push_str("<p>Per view:</p>");
    }
    h.push_str("<ul>");
    for c in report.tradeoff() {
        let _ = write!(h, "<li>{}</li>", escape_html(&c.sentence()));
    }
    h.push_str("</ul>\n");
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
