//! Error-against-time plots as PNG, drawn without text (no system fonts needed): log-log axes with grey
//! grid lines at powers of ten (ticks at 2..9 lighter), one colour per method (see [`colour`]; the report
//! carries the legend and the axis ranges), a line per (method, view) through its points in spp order and a
//! dot per point.

use image::ImageEncoder;
use plotters::prelude::*;

use crate::tradeoff::{ErrorMetric, curve};
use crate::{Error, Result, Row};

/// Colours of the methods in order (the noisy input usually first, in black); repeats after 8.
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

/// The colour of the `i`-th method of a plot, as RGB.
pub fn colour(i: usize) -> (u8, u8, u8) {
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

/// Draws `metric` against seconds (render + denoise) for `methods` (colour `i` for `methods[i]`) into a
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
    {
        let root = BitMapBackend::with_buffer(&mut buf, (width, height)).into_drawing_area();
        let err = |e: DrawingAreaErrorKind<_>| Error::Picture(format!("drawing the {} plot: {e:?}", metric.label()));
        let mut chart = ChartBuilder::on(&root).margin(12).build_cartesian_2d(x_lo..x_hi, y_lo..y_hi).map_err(err)?;
        let light = RGBColor(232, 232, 232);
        let dark = RGBColor(160, 160, 160);
        for decade in (x_lo as i32)..(x_hi as i32) {
            for m in 1..10 {
                let x = f64::from(decade) + f64::from(m).log10();
                let c = if m == 1 { dark } else { light };
                chart.draw_series(LineSeries::new([(x, y_lo), (x, y_hi)], c)).map_err(err)?;
            }
        }
        for decade in (y_lo as i32)..(y_hi as i32) {
            for m in 1..10 {
                let y = f64::from(decade) + f64::from(m).log10();
                let c = if m == 1 { dark } else { light };
                chart.draw_series(LineSeries::new([(x_lo, y), (x_hi, y)], c)).map_err(err)?;
            }
        }
        let frame = [(x_lo, y_lo), (x_hi, y_lo), (x_hi, y_hi), (x_lo, y_hi), (x_lo, y_lo)];
        chart.draw_series(LineSeries::new(frame, BLACK)).map_err(err)?;
        for (i, points) in series(rows, methods, metric) {
            let (r, g, b) = colour(i);
            let c = RGBColor(r, g, b);
            let xy: Vec<(f64, f64)> = points.iter().map(|p| (p.seconds.log10(), p.error.log10())).collect();
            chart.draw_series(LineSeries::new(xy.clone(), c.stroke_width(2))).map_err(err)?;
            chart.draw_series(xy.into_iter().map(|p| Circle::new(p, 4, c.filled()))).map_err(err)?;
        }
        root.present().map_err(err)?;
    }
    png_rgb8(&buf, width, height)
}

/// Encodes 8-bit RGB pixels as PNG.
pub fn png_rgb8(rgb: &[u8], width: u32, height: u32) -> Result<Vec<u8>> {
    let mut png = Vec::new();
    image::codecs::png::PngEncoder::new(&mut png)
        .write_image(rgb, width, height, image::ExtendedColorType::Rgb8)
        .map_err(|e| Error::Picture(format!("encoding a {width}x{height} PNG: {e}")))?;
    Ok(png)
}
