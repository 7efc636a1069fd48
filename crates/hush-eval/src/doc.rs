//! A report as typed blocks (headings, paragraphs, lists, tables with images in their cells), written as
//! Markdown by [`Document::to_markdown`] and as one self-contained page by [`crate::html::document_to_html`].
//! The sweep reports ([`crate::sweep`]) are documents; nothing here reads Markdown back.

use std::fmt::Write as _;

/// A piece of running text.
#[derive(Clone, Debug, PartialEq)]
pub enum Inline {
    Text(String),
    /// Code: command lines, flags, names of files (`…` in Markdown).
    Code(String),
    Bold(String),
    /// An image file, relative to the report's folder.
    Image {
        alt: String,
        path: String,
    },
    /// A link to another report, relative to this one; a link to a `report.md` goes to its `report.html`
    /// in HTML.
    Link {
        text: String,
        href: String,
    },
}

/// Running text: a sequence of [`Inline`]s.
pub type Text = Vec<Inline>;

/// Plain text.
pub fn text(s: impl Into<String>) -> Text {
    vec![Inline::Text(s.into())]
}

/// One image as text (e.g. a table cell).
pub fn image(alt: impl Into<String>, path: impl Into<String>) -> Text {
    vec![Inline::Image { alt: alt.into(), path: path.into() }]
}

/// A block of a document.
#[derive(Clone, Debug, PartialEq)]
pub enum Block {
    /// A heading of level 1 (the title) or 2 (a section).
    Heading(u8, Text),
    Paragraph(Text),
    List(Vec<Text>),
    Table(Grid),
}

/// A table of rich cells; `right[i]` right-aligns column `i` (numbers).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Grid {
    pub header: Vec<String>,
    pub right: Vec<bool>,
    pub rows: Vec<Vec<Text>>,
}

impl Grid {
    /// A table whose columns are right-aligned where `right` says.
    pub fn new(header: Vec<String>, right: Vec<bool>) -> Grid {
        Grid { header, right, rows: Vec::new() }
    }

    /// A [`crate::Table`]: its first column text, the others numbers; its links are left out.
    pub fn of_table(t: &crate::Table) -> Grid {
        Grid {
            header: t.header.iter().map(|h| h.to_string()).collect(),
            right: (0..t.header.len()).map(|i| i > 0).collect(),
            rows: t.rows.iter().map(|r| r.iter().map(|c| text(c.clone())).collect()).collect(),
        }
    }
}

/// A report: a title (of the HTML page) and its blocks.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Document {
    pub title: String,
    pub blocks: Vec<Block>,
}

impl Document {
    pub fn push(&mut self, block: Block) {
        self.blocks.push(block);
    }

    /// The document as Markdown, blocks separated by an empty line.
    pub fn to_markdown(&self) -> String {
        let mut md = String::new();
        for block in &self.blocks {
            match block {
                Block::Heading(level, t) => {
                    let _ = writeln!(md, "{} {}", "#".repeat(usize::from(*level)), inline_md(t, false));
                }
                Block::Paragraph(t) => {
                    let _ = writeln!(md, "{}", inline_md(t, false));
                }
                Block::List(items) => {
                    for item in items {
                        let _ = writeln!(md, "- {}", inline_md(item, false));
                    }
                }
                Block::Table(g) => {
                    let _ = writeln!(md, "| {} |", g.header.join(" | "));
                    md.push('|');
                    for i in 0..g.header.len() {
                        md.push_str(if g.right.get(i).copied().unwrap_or(false) { "--:|" } else { "---|" });
                    }
                    md.push('\n');
                    for row in &g.rows {
                        let cells: Vec<String> = row.iter().map(|c| inline_md(c, true)).collect();
                        let _ = writeln!(md, "| {} |", cells.join(" | "));
                    }
                }
            }
            md.push('\n');
        }
        md
    }
}

/// Running text as Markdown; in a table cell `|` is escaped and line breaks flattened.
fn inline_md(t: &Text, cell: bool) -> String {
    let plain = |s: &str| if cell { crate::report::md_text(s) } else { s.to_string() };
    t.iter()
        .map(|i| match i {
            Inline::Text(s) => plain(s),
            Inline::Code(s) => format!("`{s}`"),
            Inline::Bold(s) => format!("**{}**", plain(s)),
            Inline::Image { alt, path } => format!("![{}]({})", plain(alt), path.replace(' ', "%20")),
            Inline::Link { text, href } => format!("[{}]({})", plain(text), href.replace(' ', "%20")),
        })
        .collect()
}
