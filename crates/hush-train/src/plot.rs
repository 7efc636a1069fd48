//! The loss curves as an SVG chart ([`hush_plot`]): x the epoch, y the loss on a log scale, the training
//! loss in blue, the test loss in red with a dot per evaluation, a legend in the figure. The numbers
//! themselves are in `metrics.csv`.

use hush_plot::{Axis, Chart, Series};

use crate::EpochRow;

/// The training and test losses of `rows` as an SVG chart of `width`×`height`. Non-positive and non-finite
/// losses are left out (log scale).
pub fn plot_losses(rows: &[EpochRow], width: u32, height: u32) -> String {
    let train: Vec<(f64, f64)> = rows.iter().map(|r| (r.epoch as f64, r.train_loss)).collect();
    let test: Vec<(f64, f64)> = rows.iter().filter_map(|r| Some((r.epoch as f64, r.test_loss?))).collect();
    let chart = Chart {
        title: "Loss per epoch".into(),
        x: Axis::linear("epoch"),
        y: Axis::log("loss (the run's training loss, unitless)"),
        series: vec![
            Series { dots: false, ..Series::line("training loss (epoch mean)", hush_plot::color(1), train) },
            Series::line("test loss", hush_plot::color(2), test),
        ],
    };
    chart.to_svg(width, height)
}
