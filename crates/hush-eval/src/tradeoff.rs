//! Error against run time: what a denoiser saves compared with rendering longer.
//!
//! Raw path tracing's curve for a view is its noisy images along the spp ladder: points (render seconds,
//! error). Between two rungs the curve is interpolated linearly in log(seconds)–log(error) (and log(spp)), the
//! natural scale for Monte-Carlo error, which falls as a power of time (relMSE ∝ 1/t). It is never
//! extrapolated: an error below the last rung or above the first is reported as such.
//!
//! A denoiser at input spp s costs render seconds at s + denoise seconds and reaches some error e. Compared
//! with raw path tracing:
//! * equal error: the time raw path tracing needs to reach e, its spp, and the denoiser's time as a
//!   percentage of it ("reaches the error of raw N spp in X % of its time");
//! * equal time: raw path tracing's error after the denoiser's seconds.
//!
//! ```
//! use hush_eval::tradeoff::{Point, Reach, time_to_reach};
//!
//! // relMSE = 1 / t exactly, one rung per doubling of spp (1 s per spp).
//! let raw: Vec<Point> = [1.0, 2.0, 4.0, 8.0].iter().map(|&t| Point { spp: t, seconds: t, error: 1.0 / t }).collect();
//! let Reach::At { seconds, spp } = time_to_reach(&raw, 1.0 / 3.0) else { panic!() };
//! assert!((seconds - 3.0).abs() < 1e-12 && (spp - 3.0).abs() < 1e-12);
//! assert_eq!(time_to_reach(&raw, 0.01), Reach::BelowLadder);
//! ```

use std::fmt::Write as _;

use serde::{Deserialize, Serialize};

use crate::Row;

/// The error measures plotted against time.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ErrorMetric {
    /// relMSE on linear HDR.
    RelMse,
    /// 1 − SSIM on tonemapped images.
    OneMinusSsim,
}

impl ErrorMetric {
    pub const ALL: [ErrorMetric; 2] = [ErrorMetric::RelMse, ErrorMetric::OneMinusSsim];

    /// The name used in files and JSON: `rel_mse`, `one_minus_ssim`.
    pub fn key(self) -> &'static str {
        match self {
            ErrorMetric::RelMse => "rel_mse",
            ErrorMetric::OneMinusSsim => "one_minus_ssim",
        }
    }

    /// The name shown to people: `relMSE`, `1 − SSIM`.
    pub fn label(self) -> &'static str {
        match self {
            ErrorMetric::RelMse => "relMSE",
            ErrorMetric::OneMinusSsim => "1 − SSIM",
        }
    }

    /// This error of a row.
    pub fn of(self, row: &Row) -> f64 {
        match self {
            ErrorMetric::RelMse => row.rel_mse,
            ErrorMetric::OneMinusSsim => 1.0 - row.ssim,
        }
    }
}

/// One point of an error-against-time curve.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Point {
    /// Samples per pixel of the (input) render.
    pub spp: f64,
    pub seconds: f64,
    pub error: f64,
}

impl Point {
    fn usable(&self) -> bool {
        [self.spp, self.seconds, self.error].iter().all(|v| v.is_finite() && *v > 0.0)
    }
}

/// Where raw path tracing reaches an error.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Reach {
    /// Between two rungs of the ladder, interpolated.
    At { seconds: f64, spp: f64 },
    /// The error is lower than every rung reaches: it would need more spp than the ladder has (not
    /// extrapolated).
    BelowLadder,
    /// The error is higher than the first rung's: raw path tracing reaches it before its first rung (not
    /// extrapolated).
    AboveLadder,
    /// Fewer than two usable rungs: no curve to interpolate.
    NoLadder,
}

impl Reach {
    fn status(self) -> &'static str {
        match self {
            Reach::At { .. } => "interpolated",
            Reach::BelowLadder => "below_ladder",
            Reach::AboveLadder => "above_ladder",
            Reach::NoLadder => "no_ladder",
        }
    }
}

/// Raw path tracing's curve for one view and metric: its noisy rows with a render time, sorted by spp;
/// points with a non-positive or non-finite value are left out (log scale).
pub fn raw_curve(rows: &[Row], view: &str, metric: ErrorMetric) -> Vec<Point> {
    curve(rows, view, crate::report::NOISY, metric)
}

/// A method's points for one view and metric (seconds = render + denoise), sorted by spp.
pub fn curve(rows: &[Row], view: &str, method: &str, metric: ErrorMetric) -> Vec<Point> {
    let mut points: Vec<Point> = rows
        .iter()
        .filter(|r| r.view == view && r.method == method)
        .filter_map(|r| Some(Point { spp: f64::from(r.spp), seconds: r.total_seconds()?, error: metric.of(r) }))
        .filter(Point::usable)
        .collect();
    points.sort_by(|a, b| a.spp.total_cmp(&b.spp));
    points
}

/// The first time along the ladder (in spp order) at which raw path tracing's interpolated curve reaches
/// `error`. Rungs are joined in log-log; a noisy ladder whose error rises between rungs is followed as is.
pub fn time_to_reach(raw: &[Point], error: f64) -> Reach {
    if raw.len() < 2 || !(error.is_finite() && error > 0.0) {
        return Reach::NoLadder;
    }
    if error > raw[0].error {
        return Reach::AboveLadder;
    }
    let le = error.ln();
    for pair in raw.windows(2) {
        let (a, b) = (pair[0], pair[1]);
        let (lo, hi) = (a.error.min(b.error), a.error.max(b.error));
        if error < lo || error > hi {
            continue;
        }
        let f = if a.error == b.error { 0.0 } else { (le - a.error.ln()) / (b.error.ln() - a.error.ln()) };
        let lerp = |x: f64, y: f64| (x.ln() + f * (y.ln() - x.ln())).exp();
        return Reach::At { seconds: lerp(a.seconds, b.seconds), spp: lerp(a.spp, b.spp) };
    }
    Reach::BelowLadder
}

/// Raw path tracing's error after `seconds`, interpolated in log-log between the first two rungs (in spp
/// order) whose times enclose it; `None` outside the ladder's times.
pub fn error_at(raw: &[Point], seconds: f64) -> Option<f64> {
    if !(seconds.is_finite() && seconds > 0.0) {
        return None;
    }
    let ls = seconds.ln();
    raw.windows(2).find_map(|pair| {
        let (a, b) = (pair[0], pair[1]);
        let (lo, hi) = (a.seconds.min(b.seconds), a.seconds.max(b.seconds));
        if seconds < lo || seconds > hi {
            return None;
        }
        let f = if a.seconds == b.seconds { 0.0 } else { (ls - a.seconds.ln()) / (b.seconds.ln() - a.seconds.ln()) };
        Some((a.error.ln() + f * (b.error.ln() - a.error.ln())).exp())
    })
}

/// One denoiser result compared with raw path tracing (one entry of `summary.json`'s `tradeoff`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Comparison {
    pub view: String,
    pub method: String,
    /// The denoiser's input spp.
    pub spp: u32,
    pub metric: ErrorMetric,
    /// Render + denoise seconds.
    pub seconds: f64,
    pub error: f64,
    /// Raw path tracing's (interpolated) seconds to the same error.
    pub raw_seconds: Option<f64>,
    /// Raw path tracing's (interpolated) spp at the same error.
    pub raw_spp: Option<f64>,
    /// `100 · seconds / raw_seconds`.
    pub time_percent: Option<f64>,
    /// Raw path tracing's error after `seconds` (equal time).
    pub raw_error_same_time: Option<f64>,
    /// `interpolated`, `below_ladder`, `above_ladder` or `no_ladder` (see [`Reach`]).
    pub status: String,
    /// For `below_ladder`: the ladder's highest spp, whose error this one is below ...
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub top_spp: Option<f64>,
    /// ... and `100 · seconds / ` that rung's seconds: raw path tracing would need more than that rung to reach
    /// this error, so this is an upper bound on the share of raw time ([`Comparison::time_percent`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub top_time_percent: Option<f64>,
}

impl Comparison {
    /// One sentence for the report.
    pub fn sentence(&self) -> String {
        let mut s = format!(
            "{} {} at {} spp ({}: {:.3e} in {:.3} s): ",
            self.view,
            self.method,
            self.spp,
            self.metric.label(),
            self.error,
            self.seconds
        );
        match (self.raw_spp, self.time_percent) {
            (Some(spp), Some(pct)) => {
                let _ = write!(s, "reaches the error of raw {spp:.1} spp in {pct:.1} % of its time");
            }
            _ => {
                if let (Some(top), Some(pct)) = (self.top_spp, self.top_time_percent) {
                    let _ = write!(
                        s,
                        "below raw path tracing's error at the ladder's highest spp ({top:.0}) in {pct:.1} % of that \
                         render's time; "
                    );
                }
                s.push_str(match self.status.as_str() {
                    "below_ladder" => {
                        "raw path tracing does not reach this error within its spp ladder (not extrapolated)"
                    }
                    "above_ladder" => "raw path tracing is already better at its lowest spp",
                    _ => "no raw spp ladder to compare with (fewer than two rungs with render times)",
                });
            }
        }
        match self.raw_error_same_time {
            Some(e) => {
                let _ = write!(s, "; in the same time raw path tracing has {e:.3e} ({:.2}× the error)", e / self.error);
            }
            None => s.push_str("; equal time lies outside the raw ladder's times"),
        }
        s
    }
}

/// Every denoiser result of `rows` compared with raw path tracing of its view, per metric.
pub fn compare_to_raw(rows: &[Row]) -> Vec<Comparison> {
    let mut out = Vec::new();
    for metric in ErrorMetric::ALL {
        let mut raws: Vec<(&str, Vec<Point>)> = Vec::new();
        for row in rows.iter().filter(|r| r.is_denoiser()) {
            let (Some(seconds), error) = (row.total_seconds(), metric.of(row)) else { continue };
            let raw = match raws.iter().find(|(v, _)| *v == row.view) {
                Some((_, raw)) => raw,
                None => {
                    raws.push((&row.view, raw_curve(rows, &row.view, metric)));
                    &raws.last().expect("just pushed").1
                }
            };
            let reach = time_to_reach(raw, error);
            let (raw_seconds, raw_spp) = match reach {
                Reach::At { seconds, spp } => (Some(seconds), Some(spp)),
                _ => (None, None),
            };
            // The rungs are in spp order: the last is the ladder's highest.
            let top = raw.last().filter(|_| reach == Reach::BelowLadder);
            out.push(Comparison {
                view: row.view.clone(),
                method: row.method.clone(),
                spp: row.spp,
                metric,
                seconds,
                error,
                raw_seconds,
                raw_spp,
                time_percent: raw_seconds.map(|t| 100.0 * seconds / t),
                raw_error_same_time: error_at(raw, seconds),
                status: reach.status().into(),
                top_spp: top.map(|p| p.spp),
                top_time_percent: top.map(|p| 100.0 * seconds / p.seconds),
            });
        }
    }
    out
}

/// `error_vs_time.csv`: one line per row with a render time (noisy and denoisers, not the reference):
/// `view,method,spp,render_seconds,denoise_seconds,seconds,rel_mse,one_minus_ssim`; empty cells for
/// missing values. Names are quoted when they hold a comma, quote or line break.
pub fn to_csv(rows: &[Row]) -> String {
    let mut csv = String::from("view,method,spp,render_seconds,denoise_seconds,seconds,rel_mse,one_minus_ssim\n");
    let num = |v: Option<f64>| v.map_or(String::new(), |v| format!("{v}"));
    for r in rows.iter().filter(|r| r.method != crate::report::REFERENCE) {
        let Some(seconds) = r.total_seconds() else { continue };
        let _ = writeln!(
            csv,
            "{},{},{},{},{},{seconds},{},{}",
            csv_field(&r.view),
            csv_field(&r.method),
            r.spp,
            num(r.render_seconds),
            num(r.denoise_seconds),
            r.rel_mse,
            1.0 - r.ssim
        );
    }
    csv
}

/// A CSV field (RFC 4180): quoted, with quotes doubled, when it holds a comma, quote or line break.
pub fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n', '\r']) { format!("\"{}\"", s.replace('"', "\"\"")) } else { s.to_string() }
}

/// The comparisons of one denoiser at one spp and one metric, over the views.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Overview {
    pub method: String,
    pub spp: u32,
    pub metric: ErrorMetric,
    /// How many views were compared.
    pub views: usize,
    /// How many of them raw path tracing reaches within its ladder (the medians below are over these).
    pub interpolated: usize,
    /// Median of `time_percent` over the interpolated views.
    pub median_time_percent: Option<f64>,
    /// Median of `raw_spp` over the interpolated views.
    pub median_raw_spp: Option<f64>,
    /// Median over the views with an equal-time error of raw path tracing's error ÷ the denoiser's.
    pub median_error_ratio_same_time: Option<f64>,
    /// Over the views below the ladder: the median of `top_time_percent`, and the lowest of their ladders'
    /// highest spp.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub median_top_time_percent: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub top_spp: Option<f64>,
}

/// Groups `comparisons` by (metric, method, spp), in order of first appearance, with medians over views.
pub fn overview(comparisons: &[Comparison]) -> Vec<Overview> {
    let mut keys: Vec<(ErrorMetric, &str, u32)> = Vec::new();
    for c in comparisons {
        if !keys.contains(&(c.metric, c.method.as_str(), c.spp)) {
            keys.push((c.metric, &c.method, c.spp));
        }
    }
    keys.into_iter()
        .map(|(metric, method, spp)| {
            let group: Vec<&Comparison> =
                comparisons.iter().filter(|c| c.metric == metric && c.method == method && c.spp == spp).collect();
            let median_of = |f: fn(&Comparison) -> Option<f64>| median(group.iter().filter_map(|c| f(c)).collect());
            Overview {
                method: method.to_string(),
                spp,
                metric,
                views: group.len(),
                interpolated: group.iter().filter(|c| c.time_percent.is_some()).count(),
                median_time_percent: median_of(|c| c.time_percent),
                median_raw_spp: median_of(|c| c.raw_spp),
                median_error_ratio_same_time: median_of(|c| Some(c.raw_error_same_time? / c.error)),
                median_top_time_percent: median_of(|c| c.top_time_percent),
                top_spp: group.iter().filter_map(|c| c.top_spp).min_by(f64::total_cmp),
            }
        })
        .collect()
}

/// The median (mean of the middle two for an even count); `None` for no values.
fn median(mut values: Vec<f64>) -> Option<f64> {
    values.retain(|v| v.is_finite());
    if values.is_empty() {
        return None;
    }
    values.sort_by(f64::total_cmp);
    let n = values.len();
    Some(if n % 2 == 1 { values[n / 2] } else { 0.5 * (values[n / 2 - 1] + values[n / 2]) })
}
