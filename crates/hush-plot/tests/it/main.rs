//! hush-plot's integration tests: what a reader of a chart sees, read back from the SVG's text items.

use hush_plot::{Axis, Chart, Series, color, texts};

fn chart(series: Vec<Series>) -> Chart {
    Chart {
        title: "relMSE against time".into(),
        x: Axis::log("render + denoise time (s)"),
        y: Axis::log("relMSE"),
        series,
    }
}

#[test]
fn a_chart_has_its_title_axis_titles_and_legend_as_text() {
    let svg = chart(vec![
        Series::line("noisy", color(0), vec![(0.1, 0.5), (0.4, 0.1), (1.6, 0.02)]),
        Series::line("noisy", color(0), vec![(0.2, 0.3), (0.8, 0.05)]),
        Series::line("oidn <rt>", color(1), vec![(0.3, 0.01)]),
    ])
    .to_svg(640, 420);
    assert_eq!(texts(&svg, "title"), ["relMSE against time"]);
    assert_eq!(texts(&svg, "x-title"), ["render + denoise time (s) (log scale)"]);
    assert_eq!(texts(&svg, "y-title"), ["relMSE (log scale)"]);
    // One entry per name, in order, escaped in the file and read back as written.
    assert_eq!(texts(&svg, "legend"), ["noisy", "oidn <rt>"]);
    assert!(svg.contains("oidn &lt;rt&gt;") && !svg.contains("<rt>"));
    // x spans 0.1 to 1.6 s: decades 0.1 to 10; y 0.01 to 0.5: decades 0.01 to 1.
    let ticks = texts(&svg, "tick");
    for t in ["0.1", "1", "10", "0.01"] {
        assert!(ticks.iter().any(|x| x == t), "tick {t} in {ticks:?}");
    }
    assert_eq!(svg.matches("<polyline").count(), 2, "the single point is a dot only");
    assert_eq!(svg.matches("<circle").count(), 6 + 2, "a dot per point and per legend entry");
}

#[test]
fn log_axes_leave_out_what_they_cannot_show() {
    let svg = chart(vec![Series::line("a", color(1), vec![(1.0, 0.0), (f64::NAN, 1.0), (2.0, -1.0), (4.0, 0.1)])])
        .to_svg(400, 300);
    // Only (4, 0.1) is usable: one dot in the data plus one in the legend.
    assert_eq!(svg.matches("<circle").count(), 2, "{svg}");
    let empty = chart(vec![Series::line("a", color(1), vec![(1.0, f64::INFINITY)])]).to_svg(400, 300);
    assert_eq!(texts(&empty, "note"), ["no point to plot"]);
    assert_eq!(texts(&empty, "legend"), ["a"]);
}

#[test]
fn linear_axes_get_round_ticks_and_say_nothing_of_logs() {
    let c = Chart {
        title: "loss".into(),
        x: Axis::linear("epoch"),
        y: Axis::log("loss (L1)"),
        series: vec![Series::line("train", color(1), (1..=37).map(|e| (f64::from(e), 1.0 / f64::from(e))).collect())],
    };
    let svg = c.to_svg(500, 300);
    assert_eq!(texts(&svg, "x-title"), ["epoch"]);
    let ticks = texts(&svg, "tick");
    for t in ["0", "10", "20", "30", "40"] {
        assert!(ticks.iter().any(|x| x == t), "tick {t} in {ticks:?}");
    }
    assert!(!ticks.iter().any(|x| x == "37"), "ticks are round: {ticks:?}");
}

#[test]
fn the_legend_avoids_the_points() {
    // Points crowd the top right: the legend goes elsewhere.
    let points: Vec<(f64, f64)> = (0..20).map(|i| (9.0 + f64::from(i) * 0.05, 0.9 + f64::from(i) * 0.005)).collect();
    let c = Chart {
        title: "t".into(),
        x: Axis::linear("x (m)"),
        y: Axis::linear("y (m)"),
        series: vec![Series::line("crowded", color(2), points), Series::line("origin", color(3), vec![(0.0, 0.0)])],
    };
    let svg = c.to_svg(600, 400);
    let at = svg.find("<g class=\"legend-box\"><rect x=\"").unwrap() + 32;
    let x: f64 = svg[at..].split('"').next().unwrap().parse().unwrap();
    assert!(x < 300.0, "the legend box starts at x = {x}, over the crowded top right");
}
