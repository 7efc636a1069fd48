//! A PNG of the loss curves, drawn without text (no system fonts needed): x is the epoch, y the loss on a
//! log scale with grey lines at each power of ten (darker at 1, 0.1, 0.01, ...), the training loss in blue,
//! the test loss in red with a dot per evaluation. The numbers themselves are in `metrics.csv`.

use image::ImageEncoder;
use plotters::prelude::*;

use crate::EpochRow;

const TRAIN: RGBColor = RGBColor(31, 119, 180);
const TEST: RGBColor = RGBColor(214, 39, 40);

/// Draws the training and test losses of `rows` into a `width`×`height` PNG. Non-positive and non-finite
/// losses are left out (log scale).
pub fn plot_losses(rows: &[EpochRow], width: u32, height: u32) -> Result<Vec<u8>, String> {
    let train: Vec<(f64, f64)> =
        rows.iter().map(|r| (r.epoch as f64, r.train_loss)).filter(|p| p.1.is_finite() && p.1 > 0.0).collect();
    let test: Vec<(f64, f64)> = rows
        .iter()
        .filter_map(|r| Some((r.epoch as f64, r.test_loss?)))
        .filter(|p| p.1.is_finite() && p.1 > 0.0)
        .collect();
    let all = || train.iter().chain(&test);
    let (lo, hi) = all().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| (lo.min(p.1), hi.max(p.1)));
    let x_max = all().fold(1.0f64, |m, p| m.max(p.0));
    let (lo, hi) = if lo.is_finite() {
        (lo.log10().floor(), hi.log10().ceil().max(lo.log10().floor() + 1.0))
    } else {
        (-2.0, 0.0)
    };
    let mut buf = vec![255u8; (width * height * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (width, height)).into_drawing_area();
        let err = |e: DrawingAreaErrorKind<_>| format!("drawing the loss plot: {e:?}");
        let mut chart = ChartBuilder::on(&root).margin(12).build_cartesian_2d(0.0..x_max, lo..hi).map_err(err)?;
        let grey = |k: f64| if k.fract() == 0.0 { RGBColor(170, 170, 170) } else { RGBColor(230, 230, 230) };
        // Grid: log10 of 1..9 × each decade.
        let mut d = lo;
        while d < hi {
            for m in 1..10 {
                let y = d + (m as f64).log10();
                let level = if m == 1 { d } else { 0.5 };
                chart.draw_series(LineSeries::new([(0.0, y), (x_max, y)], grey(level))).map_err(err)?;
            }
            d += 1.0;
        }
        chart.draw_series(LineSeries::new([(0.0, hi), (x_max, hi)], grey(hi))).map_err(err)?;
        let frame = [(0.0, lo), (x_max, lo), (x_max, hi), (0.0, hi), (0.0, lo)];
        chart.draw_series(LineSeries::new(frame, BLACK)).map_err(err)?;
        let log = |v: &[(f64, f64)]| v.iter().map(|&(x, y)| (x, y.log10())).collect::<Vec<_>>();
        chart.draw_series(LineSeries::new(log(&train), TRAIN.stroke_width(2))).map_err(err)?;
        chart.draw_series(LineSeries::new(log(&test), TEST.stroke_width(2))).map_err(err)?;
        chart.draw_series(log(&test).into_iter().map(|p| Circle::new(p, 3, TEST.filled()))).map_err(err)?;
        root.present().map_err(err)?;
    }
    let mut png = Vec::new();
    image::codecs::png::PngEncoder::new(&mut png)
        .write_image(&buf, width, height, image::ExtendedColorType::Rgb8)
        .map_err(|e| format!("encoding the loss plot: {e}"))?;
    Ok(png)
}
