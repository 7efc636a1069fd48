//! Line charts as self-contained SVG, the one plotting path of hush: the evaluation's error against time,
//! the training loss, the sweeps' loss curves.
//!
//! A [`Chart`] explains itself: a title, axis titles that carry their units, log axes labelled as such
//! ("(log scale)" after the title, ticks at powers of ten), and a legend inside the plot area, in the corner
//! that covers the fewest points. Text stays text (`<text>` elements with the classes `title`, `x-title`,
//! `y-title`, `tick` and `legend`), so a reader can search it, a browser draws it in its own font, and a test
//! can read it. Nothing is loaded: no fonts, no styles, no scripts.
//!
//! ```
//! use hush_plot::{Axis, Chart, Series};
//! let chart = Chart {
//!     title: "Loss".into(),
//!     x: Axis::linear("epoch"),
//!     y: Axis::log("loss"),
//!     series: vec![Series::line("train", hush_plot::color(1), vec![(1.0, 0.1), (2.0, 0.05)])],
//! };
//! let svg = chart.to_svg(640, 400);
//! assert!(svg.contains(">loss (log scale)</text>"));
//! ```

use std::fmt::Write as _;

/// Colors of series in order (the first black, for the noisy input or a baseline); repeats after 8.
pub const PALETTE: [(u8, u8, u8); 8] = [
    (0, 0, 0),
    (31, 119, 180),
    (214, 39, 40),
    (44, 160, 44),
    (255, 127, 14),
    (148, 103, 189),
    (140, 86, 75),
    (227, 119, 194),
];

/// The `i`-th color of [`PALETTE`].
pub fn color(i: usize) -> (u8, u8, u8) {
    PALETTE[i % PALETTE.len()]
}

/// `#rrggbb`.
pub fn hex((r, g, b): (u8, u8, u8)) -> String {
    format!("#{r:02x}{g:02x}{b:02x}")
}

/// How an axis maps values.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Scale {
    Linear,
    /// Base 10; values ≤ 0 are left out.
    Log,
}

/// One axis: its title (with the unit, e.g. `"time (s)"`) and scale.
#[derive(Clone, Debug, PartialEq)]
pub struct Axis {
    pub title: String,
    pub scale: Scale,
}

impl Axis {
    pub fn linear(title: impl Into<String>) -> Axis {
        Axis { title: title.into(), scale: Scale::Linear }
    }

    pub fn log(title: impl Into<String>) -> Axis {
        Axis { title: title.into(), scale: Scale::Log }
    }

    /// The title as drawn: a log axis says so.
    pub fn label(&self) -> String {
        match self.scale {
            Scale::Linear => self.title.clone(),
            Scale::Log => format!("{} (log scale)", self.title),
        }
    }

    fn usable(&self, v: f64) -> bool {
        v.is_finite() && (self.scale == Scale::Linear || v > 0.0)
    }

    fn map(&self, v: f64) -> f64 {
        match self.scale {
            Scale::Linear => v,
            Scale::Log => v.log10(),
        }
    }
}

/// One line of a chart. Series with the same name share one legend entry (e.g. one method over several views).
#[derive(Clone, Debug, PartialEq)]
pub struct Series {
    pub name: String,
    pub color: (u8, u8, u8),
    /// In drawing order; points an axis cannot show (non-finite, or ≤ 0 on a log axis) are left out.
    pub points: Vec<(f64, f64)>,
    /// A dot at every point.
    pub dots: bool,
}

impl Series {
    /// A line with a dot at every point.
    pub fn line(name: impl Into<String>, color: (u8, u8, u8), points: Vec<(f64, f64)>) -> Series {
        Series { name: name.into(), color, points, dots: true }
    }
}

/// A line chart.
#[derive(Clone, Debug, PartialEq)]
pub struct Chart {
    pub title: String,
    pub x: Axis,
    pub y: Axis,
    pub series: Vec<Series>,
}

/// Where the plot area lies in the picture, and the data range it shows (in mapped units: log10 on log axes).
struct Frame {
    left: f64,
    top: f64,
    right: f64,
    bottom: f64,
    x: (f64, f64),
    y: (f64, f64),
}

impl Frame {
    fn px(&self, x: f64) -> f64 {
        self.left + (x - self.x.0) / (self.x.1 - self.x.0) * (self.right - self.left)
    }

    fn py(&self, y: f64) -> f64 {
        self.bottom - (y - self.y.0) / (self.y.1 - self.y.0) * (self.bottom - self.top)
    }
}

const FONT: f64 = 13.0;

impl Chart {
    /// The usable points of each series, mapped (log10 on log axes).
    fn mapped(&self) -> Vec<Vec<(f64, f64)>> {
        self.series
            .iter()
            .map(|s| {
                s.points
                    .iter()
                    .filter(|(x, y)| self.x.usable(*x) && self.y.usable(*y))
                    .map(|&(x, y)| (self.x.map(x), self.y.map(y)))
                    .collect()
            })
            .collect()
    }

    /// The chart as an SVG document of `width`×`height` pixels (a `viewBox`, so it scales).
    pub fn to_svg(&self, width: u32, height: u32) -> String {
        let (w, h) = (f64::from(width.max(200)), f64::from(height.max(150)));
        let mapped = self.mapped();
        let all: Vec<(f64, f64)> = mapped.iter().flatten().copied().collect();
        let x = range(all.iter().map(|p| p.0), self.x.scale);
        let y = range(all.iter().map(|p| p.1), self.y.scale);
        let (x_ticks, y_ticks) = (ticks(x, self.x.scale), ticks(y, self.y.scale));
        let y_tick_chars = y_ticks.iter().map(|t| t.1.chars().count()).max().unwrap_or(1) as f64;
        let f = Frame {
            left: 2.2 * FONT + 0.62 * FONT * y_tick_chars + 8.0,
            top: 2.4 * FONT,
            right: w - 12.0,
            bottom: h - 3.4 * FONT,
            x,
            y,
        };
        let mut s = String::new();
        let _ = write!(
            s,
            "<svg xmlns=\"http://www.w3.org/2000/svg\" viewBox=\"0 0 {w} {h}\" width=\"{w}\" height=\"{h}\" \
             font-family=\"sans-serif\" font-size=\"{FONT}\" role=\"img\"><title>{}</title>\
             <rect width=\"{w}\" height=\"{h}\" fill=\"white\"/>",
            xml(&self.title)
        );
        let _ = write!(
            s,
            "<text class=\"title\" x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"middle\" font-size=\"{:.0}\" font-weight=\"bold\">{}</text>",
            (f.left + f.right) / 2.0,
            1.5 * FONT,
            FONT * 1.15,
            xml(&self.title)
        );
        // Grid and ticks.
        for (v, label, major) in &x_ticks {
            let px = f.px(*v);
            let stroke = if *major { "#bbb" } else { "#e8e8e8" };
            let _ = write!(
                s,
                "<line x1=\"{px:.1}\" y1=\"{:.1}\" x2=\"{px:.1}\" y2=\"{:.1}\" stroke=\"{stroke}\"/>",
                f.top, f.bottom
            );
            if !label.is_empty() {
                let _ = write!(
                    s,
                    "<text class=\"tick\" x=\"{px:.1}\" y=\"{:.1}\" text-anchor=\"middle\">{}</text>",
                    f.bottom + 1.3 * FONT,
                    xml(label)
                );
            }
        }
        for (v, label, major) in &y_ticks {
            let py = f.py(*v);
            let stroke = if *major { "#bbb" } else { "#e8e8e8" };
            let _ = write!(
                s,
                "<line x1=\"{:.1}\" y1=\"{py:.1}\" x2=\"{:.1}\" y2=\"{py:.1}\" stroke=\"{stroke}\"/>",
                f.left, f.right
            );
            if !label.is_empty() {
                let _ = write!(
                    s,
                    "<text class=\"tick\" x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"end\">{}</text>",
                    f.left - 5.0,
                    py + 0.35 * FONT,
                    xml(label)
                );
            }
        }
        let _ = write!(
            s,
            "<rect x=\"{:.1}\" y=\"{:.1}\" width=\"{:.1}\" height=\"{:.1}\" fill=\"none\" stroke=\"black\"/>",
            f.left,
            f.top,
            f.right - f.left,
            f.bottom - f.top
        );
        let _ = write!(
            s,
            "<text class=\"x-title\" x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"middle\">{}</text>",
            (f.left + f.right) / 2.0,
            h - 0.6 * FONT,
            xml(&self.x.label())
        );
        let (cx, cy) = (1.2 * FONT, (f.top + f.bottom) / 2.0);
        let _ = write!(
            s,
            "<text class=\"y-title\" x=\"{cx:.1}\" y=\"{cy:.1}\" text-anchor=\"middle\" transform=\"rotate(-90 {cx:.1} {cy:.1})\">{}</text>",
            xml(&self.y.label())
        );
        // Data.
        for (series, points) in self.series.iter().zip(&mapped) {
            let c = hex(series.color);
            if points.len() > 1 {
                let path: Vec<String> = points.iter().map(|&(x, y)| format!("{:.1},{:.1}", f.px(x), f.py(y))).collect();
                let _ = write!(
                    s,
                    "<polyline fill=\"none\" stroke=\"{c}\" stroke-width=\"2\" points=\"{}\"/>",
                    path.join(" ")
                );
            }
            if series.dots || points.len() == 1 {
                for &(x, y) in points {
                    let _ = write!(s, "<circle cx=\"{:.1}\" cy=\"{:.1}\" r=\"3.5\" fill=\"{c}\"/>", f.px(x), f.py(y));
                }
            }
        }
        if all.is_empty() {
            let _ = write!(
                s,
                "<text class=\"note\" x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"middle\" fill=\"#777\">no point to plot</text>",
                (f.left + f.right) / 2.0,
                (f.top + f.bottom) / 2.0
            );
        }
        self.legend(&mut s, &f, &all);
        s.push_str("</svg>\n");
        s
    }

    /// The legend: one entry per distinct series name, in a box in the plot area's corner that covers the
    /// fewest points.
    fn legend(&self, s: &mut String, f: &Frame, points: &[(f64, f64)]) {
        let mut entries: Vec<(&str, (u8, u8, u8))> = Vec::new();
        for series in &self.series {
            if !entries.iter().any(|(n, _)| *n == series.name) {
                entries.push((&series.name, series.color));
            }
        }
        if entries.is_empty() {
            return;
        }
        let line = 1.35 * FONT;
        let chars = entries.iter().map(|(n, _)| n.chars().count()).max().unwrap_or(0) as f64;
        let bw = (0.6 * FONT * chars + 2.6 * FONT).min(f.right - f.left - 8.0);
        let bh = line * entries.len() as f64 + 0.6 * FONT;
        let corners = [
            (f.right - bw - 6.0, f.top + 6.0),
            (f.left + 6.0, f.top + 6.0),
            (f.right - bw - 6.0, f.bottom - bh - 6.0),
            (f.left + 6.0, f.bottom - bh - 6.0),
        ];
        let covered = |(x0, y0): (f64, f64)| {
            points
                .iter()
                .filter(|(x, y)| {
                    let (px, py) = (f.px(*x), f.py(*y));
                    px >= x0 - 4.0 && px <= x0 + bw + 4.0 && py >= y0 - 4.0 && py <= y0 + bh + 4.0
                })
                .count()
        };
        let (x0, y0) = corners.into_iter().min_by_key(|c| covered(*c)).unwrap_or(corners[0]);
        let _ = write!(
            s,
            "<g class=\"legend-box\"><rect x=\"{x0:.1}\" y=\"{y0:.1}\" width=\"{bw:.1}\" height=\"{bh:.1}\" \
             fill=\"white\" fill-opacity=\"0.9\" stroke=\"#999\"/>"
        );
        for (i, (name, color)) in entries.iter().enumerate() {
            let y = y0 + 0.3 * FONT + line * (i as f64 + 0.5);
            let c = hex(*color);
            let _ = write!(
                s,
                "<line x1=\"{:.1}\" y1=\"{y:.1}\" x2=\"{:.1}\" y2=\"{y:.1}\" stroke=\"{c}\" stroke-width=\"2\"/>\
                 <circle cx=\"{:.1}\" cy=\"{y:.1}\" r=\"3.5\" fill=\"{c}\"/>\
                 <text class=\"legend\" x=\"{:.1}\" y=\"{:.1}\">{}</text>",
                x0 + 0.4 * FONT,
                x0 + 1.8 * FONT,
                x0 + 1.1 * FONT,
                x0 + 2.2 * FONT,
                y + 0.35 * FONT,
                xml(name)
            );
        }
        s.push_str("</g>");
    }
}

/// The data range of one axis in mapped units: whole decades on a log axis, a little margin on a linear one,
/// and a unit range around a single value (or `(0, 1)` / `(-1, 0)` without data).
fn range(values: impl Iterator<Item = f64>, scale: Scale) -> (f64, f64) {
    let (lo, hi) = values.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| (lo.min(v), hi.max(v)));
    if !lo.is_finite() {
        return match scale {
            Scale::Linear => (0.0, 1.0),
            Scale::Log => (-1.0, 0.0),
        };
    }
    match scale {
        Scale::Log => (lo.floor(), hi.ceil().max(lo.floor() + 1.0)),
        Scale::Linear => {
            if hi - lo < 1e-12 * lo.abs().max(1.0) {
                return (lo - 0.5 * lo.abs().max(1.0), hi + 0.5 * hi.abs().max(1.0));
            }
            let step = nice_step((hi - lo) / 6.0);
            let lo = if lo >= 0.0 && lo < 2.0 * step { 0.0 } else { (lo / step).floor() * step };
            (lo, (hi / step).ceil() * step)
        }
    }
}

/// 1, 2 or 5 times a power of ten, at least `raw`.
fn nice_step(raw: f64) -> f64 {
    let p = 10f64.powf(raw.log10().floor());
    [1.0, 2.0, 5.0, 10.0].into_iter().map(|m| m * p).find(|s| *s >= raw * 0.999).unwrap_or(10.0 * p)
}

/// Ticks in mapped units: (position, label, major). A log axis has a major, labelled tick per decade and
/// minor ones at 2..9 (labelled at 2 and 5 when it spans only one or two decades).
fn ticks((lo, hi): (f64, f64), scale: Scale) -> Vec<(f64, String, bool)> {
    match scale {
        Scale::Log => {
            let decades = (hi - lo).round() as i32;
            let mut out = Vec::new();
            for d in (lo as i32)..=(hi as i32) {
                out.push((f64::from(d), decade_label(d), true));
                if d == hi as i32 {
                    break;
                }
                for m in 2..10 {
                    let label = if decades <= 2 && (m == 2 || m == 5) {
                        number(f64::from(m) * 10f64.powi(d))
                    } else {
                        String::new()
                    };
                    out.push((f64::from(d) + f64::from(m).log10(), label, false));
                }
            }
            out
        }
        Scale::Linear => {
            let step = nice_step((hi - lo) / 6.0);
            let mut out = Vec::new();
            let mut v = (lo / step).ceil() * step;
            while v <= hi + step * 1e-9 {
                out.push((v, number(v), true));
                v += step;
            }
            out
        }
    }
}

/// `10^d` as a plain number where that is short (0.001 to 10000), else `1e-5`.
fn decade_label(d: i32) -> String {
    if (-3..=4).contains(&d) { number(10f64.powi(d)) } else { format!("1e{d}") }
}

/// A tick value without trailing zeros.
fn number(v: f64) -> String {
    if v == 0.0 {
        return "0".into();
    }
    if v.abs() >= 1e5 || v.abs() < 1e-3 {
        return format!("{v:e}");
    }
    let s = format!("{v:.6}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    s.to_string()
}

/// Escapes text for XML content and attribute values.
pub fn xml(s: &str) -> String {
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

/// The text of every `<text>` element of `svg` with the given class, unescaped: what a reader of the figure
/// sees (for tests and for checks of a written plot).
pub fn texts(svg: &str, class: &str) -> Vec<String> {
    let open = format!("<text class=\"{class}\"");
    let mut out = Vec::new();
    let mut rest = svg;
    while let Some(i) = rest.find(&open) {
        rest = &rest[i + open.len()..];
        let Some(start) = rest.find('>') else { break };
        let Some(end) = rest[start..].find("</text>") else { break };
        let inner = &rest[start + 1..start + end];
        out.push(
            inner
                .replace("&lt;", "<")
                .replace("&gt;", ">")
                .replace("&quot;", "\"")
                .replace("&#39;", "'")
                .replace("&amp;", "&"),
        );
        rest = &rest[start + end..];
    }
    out
}
