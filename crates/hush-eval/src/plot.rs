//! Error-against-time plots as PNG, drawn without fonts (no system font needed): log-log axes with grey
//! grid lines at powers of ten (2..9 lighter), each power labelled `1e-2` etc. in a built-in 3×5 pixel font
//! (seconds below, the error at the left), one color per method (see [`color`]; the report carries the
//! legend), a line per (method, view) through its points in spp order and a dot per point.

use image::ImageEncoder;
use plotters::prelude::*;

use crate::tradeoff::{ErrorMetric, curve};
use crate::{Error, Result, Row};

/// Colors of the methods in order (the noisy input usually first, in black); repeats after 8.
const PALETTE: [(u8, u8, u8); 8] = [
    (0, 0, 0),
    (31, 119, 180),
    (214, 39, 40),
    (44, 160, 44),
    (255, 127, 14),
    (148, 103, 189),
    (140, 86, 75),
    (227, 119, 194),
];

/// The color of the `i`-th method of a plot, as RGB.
pub fn series_color(i: usize) -> (u8, u8, u8) {
    PALETTE[i % PALETTE.len()]
}

/// The decades a plot's axes span: `(x_lo, x_hi, y_lo, y_hi)` as powers of ten (log10 of seconds and of
/// the error), or `None` when no row has a usable point.
pub fn decades(rows: &[Row], methods: &[&str], metric: ErrorMetric) -> Option<(f64, f64, f64, f64)> {
    let points: Vec<_> = series(rows, methods, metric).into_iter().flat_map(|(_, p)| p).collect();
    if points.is_empty() {
        return None;
    }
    let range = |f: fn(&crate::tradeoff::Point) -> f64| {
        let (lo, hi) = points
            .iter()
            .map(|p| f(p).log10())
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| (lo.min(v), hi.max(v)));
        (lo.floor(), hi.ceil().max(lo.floor() + 1.0))
    };
    let (x, y) = (range(|p| p.seconds), range(|p| p.error));
    Some((x.0, x.1, y.0, y.1))
}

/// (method index, points) for every (method, view) with points.
fn series(rows: &[Row], methods: &[&str], metric: ErrorMetric) -> Vec<(usize, Vec<crate::tradeoff::Point>)> {
    let views = crate::report::in_order(rows.iter().map(|r| r.view.as_str()));
    let mut out = Vec::new();
    for (i, method) in methods.iter().enumerate() {
        for view in &views {
            let points = curve(rows, view, method, metric);
            if !points.is_empty() {
                out.push((i, points));
            }
        }
    }
    out
}

/// Draws `metric` against seconds (render + denoise) for `methods` (color `i` for `methods[i]`) into a
/// `width`×`height` PNG. Without any usable point the plot is an empty frame.
pub fn plot_error_vs_time(
    rows: &[Row],
    methods: &[&str],
    metric: ErrorMetric,
    width: u32,
    height: u32,
) -> Result<Vec<u8>> {
    let (x_lo, x_hi, y_lo, y_hi) = decades(rows, methods, metric).unwrap_or((-1.0, 0.0, -1.0, 0.0));
    let mut buf = vec![255u8; (width * height * 3) as usize];
    let mut labels: Vec<(i32, i32, String)> = Vec::new();
    {
        let root = BitMapBackend::with_buffer(&mut buf, (width, height)).into_drawing_area();
        let err = |e: DrawingAreaErrorKind<_>| Error::Picture(format!("drawing the {} plot: {e:?}", metric.label()));
        let mut chart = ChartBuilder::on(&root)
            .margin(12)
            .margin_left(48)
            .margin_bottom(24)
            .build_cartesian_2d(x_lo..x_hi, y_lo..y_hi)
            .map_err(err)?;
        for (x, c) in grid_lines(x_lo, x_hi) {
            chart.draw_series(LineSeries::new([(x, y_lo), (x, y_hi)], c)).map_err(err)?;
        }
        for (y, c) in grid_lines(y_lo, y_hi) {
            chart.draw_series(LineSeries::new([(x_lo, y), (x_hi, y)], c)).map_err(err)?;
        }
        let frame = [(x_lo, y_lo), (x_hi, y_lo), (x_hi, y_hi), (x_lo, y_hi), (x_lo, y_lo)];
        chart.draw_series(LineSeries::new(frame, BLACK)).map_err(err)?;
        for (i, points) in series(rows, methods, metric) {
            let (r, g, b) = series_color(i);
            let c = RGBColor(r, g, b);
            let xy: Vec<(f64, f64)> = points.iter().map(|p| (p.seconds.log10(), p.error.log10())).collect();
            chart.draw_series(LineSeries::new(xy.clone(), c.stroke_width(2))).map_err(err)?;
            chart.draw_series(xy.into_iter().map(|p| Circle::new(p, 4, c.filled()))).map_err(err)?;
        }
        for d in (x_lo as i32)..=(x_hi as i32) {
            let (px, py) = chart.backend_coord(&(f64::from(d), y_lo));
            let text = format!("1e{d}");
            labels.push((px - text_width(&text) / 2, py + 6, text));
        }
        for d in (y_lo as i32)..=(y_hi as i32) {
            labels.push(y_label(chart.backend_coord(&(x_lo, f64::from(d))), d));
        }
        root.present().map_err(err)?;
    }
    for (x, y, text) in &labels {
        draw_text(&mut buf, width, height, *x, *y, text);
    }
    png_rgb8(&buf, width, height)
}

/// Log-scale grid lines between the decades `lo` and `hi` (log10 values): at 1..9 × each power of ten,
/// darker at the powers.
fn grid_lines(lo: f64, hi: f64) -> Vec<(f64, RGBColor)> {
    let mut out = Vec::new();
    for decade in (lo as i32)..(hi as i32) {
        for m in 1..10 {
            let c = if m == 1 { RGBColor(160, 160, 160) } else { RGBColor(232, 232, 232) };
            out.push((f64::from(decade) + f64::from(m).log10(), c));
        }
    }
    out
}

/// The label `1e<d>` left of the pixel `(px, py)` of the y axis.
fn y_label((px, py): (i32, i32), d: i32) -> (i32, i32, String) {
    let text = format!("1e{d}");
    (px - 6 - text_width(&text), py - GLYPH_H * LABEL_SCALE / 2, text)
}

/// Draws each series (color `i` for `series[i]`, see [`series_color`]) as a line with a dot per point, x
/// linear from 0 (labelled at 0 and its largest x), y on a log scale (labelled at each power of ten), into a
/// `width`×`height` PNG. Non-positive and non-finite y are left out; without any point the plot is an empty
/// frame. The sweeps' loss curves (x the epoch).
pub fn plot_lines(series: &[Vec<(f64, f64)>], width: u32, height: u32) -> Result<Vec<u8>> {
    let usable = |p: &&(f64, f64)| p.0.is_finite() && p.1.is_finite() && p.1 > 0.0;
    let points: Vec<(f64, f64)> = series.iter().flatten().filter(usable).copied().collect();
    let x_hi = points.iter().fold(1.0f64, |m, p| m.max(p.0)).ceil();
    let (lo, hi) = points.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| (a.min(p.1), b.max(p.1)));
    let (y_lo, y_hi) = if lo.is_finite() {
        (lo.log10().floor(), hi.log10().ceil().max(lo.log10().floor() + 1.0))
    } else {
        (-1.0, 0.0)
    };
    let mut buf = vec![255u8; (width * height * 3) as usize];
    let mut labels: Vec<(i32, i32, String)> = Vec::new();
    {
        let root = BitMapBackend::with_buffer(&mut buf, (width, height)).into_drawing_area();
        let err = |e: DrawingAreaErrorKind<_>| Error::Picture(format!("drawing a line chart: {e:?}"));
        let mut chart = ChartBuilder::on(&root)
            .margin(12)
            .margin_left(48)
            .margin_bottom(24)
            .build_cartesian_2d(0.0..x_hi, y_lo..y_hi)
            .map_err(err)?;
        for (y, c) in grid_lines(y_lo, y_hi) {
            chart.draw_series(LineSeries::new([(0.0, y), (x_hi, y)], c)).map_err(err)?;
        }
        let frame = [(0.0, y_lo), (x_hi, y_lo), (x_hi, y_hi), (0.0, y_hi), (0.0, y_lo)];
        chart.draw_series(LineSeries::new(frame, BLACK)).map_err(err)?;
        for (i, line) in series.iter().enumerate() {
            let (r, g, b) = series_color(i);
            let c = RGBColor(r, g, b);
            let xy: Vec<(f64, f64)> = line.iter().filter(usable).map(|&(x, y)| (x, y.log10())).collect();
            chart.draw_series(LineSeries::new(xy.clone(), c.stroke_width(2))).map_err(err)?;
            chart.draw_series(xy.into_iter().map(|p| Circle::new(p, 3, c.filled()))).map_err(err)?;
        }
        for x in [0.0, x_hi] {
            let (px, py) = chart.backend_coord(&(x, y_lo));
            let text = format!("{x}");
            labels.push((px - text_width(&text) / 2, py + 6, text));
        }
        for d in (y_lo as i32)..=(y_hi as i32) {
            labels.push(y_label(chart.backend_coord(&(0.0, f64::from(d))), d));
        }
        root.present().map_err(err)?;
    }
    for (x, y, text) in &labels {
        draw_text(&mut buf, width, height, *x, *y, text);
    }
    png_rgb8(&buf, width, height)
}

const GLYPH_H: i32 = 5;
const LABEL_SCALE: i32 = 2;

/// 3×5 glyphs, one row of 3 bits per line, top first: digits, `-` and `e`.
fn glyph(c: char) -> Option<[u8; 5]> {
    Some(match c {
        '0' => [0b111, 0b101, 0b101, 0b101, 0b111],
        '1' => [0b010, 0b110, 0b010, 0b010, 0b111],
        '2' => [0b111, 0b001, 0b111, 0b100, 0b111],
        '3' => [0b111, 0b001, 0b111, 0b001, 0b111],
        '4' => [0b101, 0b101, 0b111, 0b001, 0b001],
        '5' => [0b111, 0b100, 0b111, 0b001, 0b111],
        '6' => [0b111, 0b100, 0b111, 0b101, 0b111],
        '7' => [0b111, 0b001, 0b001, 0b001, 0b001],
        '8' => [0b111, 0b101, 0b111, 0b101, 0b111],
        '9' => [0b111, 0b101, 0b111, 0b001, 0b111],
        '-' => [0b000, 0b000, 0b111, 0b000, 0b000],
        'e' => [0b000, 0b111, 0b111, 0b100, 0b111],
        _ => return None,
    })
}

/// Width in pixels of `text` in the label font (4 columns per glyph, the last one blank).
fn text_width(text: &str) -> i32 {
    4 * LABEL_SCALE * text.chars().count() as i32 - LABEL_SCALE
}

/// Draws `text` in black with its top-left corner at (`x`, `y`); pixels outside the image are skipped.
fn draw_text(buf: &mut [u8], width: u32, height: u32, x: i32, y: i32, text: &str) {
    for (i, rows) in text.chars().filter_map(glyph).enumerate() {
        for (row, bits) in rows.iter().enumerate() {
            for col in 0..3 {
                if bits & (0b100 >> col) == 0 {
                    continue;
                }
                for dy in 0..LABEL_SCALE {
                    for dx in 0..LABEL_SCALE {
                        let px = x + (4 * i as i32 + col) * LABEL_SCALE + dx;
                        let py = y + row as i32 * LABEL_SCALE + dy;
                        if (0..width as i32).contains(&px) && (0..height as i32).contains(&py) {
                            let at = 3 * (py as usize * width as usize + px as usize);
                            buf[at..at + 3].fill(0);
                        }
                    }
                }
            }
        }
    }
}

/// Encodes 8-bit RGB pixels as PNG.
pub fn png_rgb8(rgb: &[u8], width: u32, height: u32) -> Result<Vec<u8>> {
    let mut png = Vec::new();
    image::codecs::png::PngEncoder::new(&mut png)
        .write_image(rgb, width, height, image::ExtendedColorType::Rgb8)
        .map_err(|e| Error::Picture(format!("encoding a {width}x{height} PNG: {e}")))?;
    Ok(png)
}
