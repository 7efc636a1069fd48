//! The evaluation's plots, drawn by [`hush_plot`] as SVG: error against time on log-log axes (a line per
//! (method, view) through its points in spp order, one color and one legend entry per method), and the
//! sweeps' loss curves. PNG encoding of pictures lives here too.

use hush_plot::{Axis, Chart, Series};
use image::ImageEncoder;

use crate::tradeoff::{ErrorMetric, curve};
use crate::{Error, Result, Row};

/// The color of the `i`-th method of a plot, as RGB.
pub fn series_color(i: usize) -> (u8, u8, u8) {
    hush_plot::color(i)
}

/// What a metric's axis says: its name and what it is computed on (the metrics have no unit).
pub fn metric_axis(metric: ErrorMetric) -> &'static str {
    match metric {
        ErrorMetric::RelMse => "relMSE (linear HDR, unitless)",
        ErrorMetric::OneMinusSsim => "1 − SSIM (tonemapped, unitless)",
    }
}

/// `metric` against seconds (render + denoise) for `methods` (color `i` for `methods[i]`), as a chart: one
/// line per (method, view) with points. Without any usable point the chart says so.
pub fn error_vs_time_chart(rows: &[Row], methods: &[&str], metric: ErrorMetric) -> Chart {
    let views = crate::report::in_order(rows.iter().map(|r| r.view.as_str()));
    let mut series = Vec::new();
    for (i, method) in methods.iter().enumerate() {
        for view in &views {
            let points: Vec<(f64, f64)> =
                curve(rows, view, method, metric).iter().map(|p| (p.seconds, p.error)).collect();
            if !points.is_empty() {
                series.push(Series::line(*method, series_color(i), points));
            }
        }
    }
    let per_view = if views.len() > 1 { format!(", a line per view ({})", views.len()) } else { String::new() };
    Chart {
        title: format!("{} against time{per_view}", metric.label()),
        x: Axis::log("render + denoise time (s)"),
        y: Axis::log(metric_axis(metric)),
        series,
    }
}

/// [`error_vs_time_chart`] as an SVG document of `width`×`height`.
pub fn plot_error_vs_time(rows: &[Row], methods: &[&str], metric: ErrorMetric, width: u32, height: u32) -> String {
    error_vs_time_chart(rows, methods, metric).to_svg(width, height)
}

/// Encodes 8-bit RGB pixels as PNG.
pub fn png_rgb8(rgb: &[u8], width: u32, height: u32) -> Result<Vec<u8>> {
    let mut png = Vec::new();
    image::codecs::png::PngEncoder::new(&mut png)
        .write_image(rgb, width, height, image::ExtendedColorType::Rgb8)
        .map_err(|e| Error::Picture(format!("encoding a {width}x{height} PNG: {e}")))?;
    Ok(png)
}
