//! Error against run time on synthetic curves whose answers are known exactly: raw path tracing with
//! relMSE = c / t is a straight line in log-log, so interpolation between rungs must be exact (to rounding).

use hush_eval::tradeoff::{self, ErrorMetric, Point, Reach, error_at, time_to_reach};
use hush_eval::{Metrics, Row};

const C: f64 = 0.5;

/// Rungs at 1, 2, 4, ..., 64 spp, 0.25 s per spp, relMSE = C / t.
fn raw() -> Vec<Point> {
    (0..7).map(|k| f64::from(1 << k)).map(|spp| Point { spp, seconds: 0.25 * spp, error: C / (0.25 * spp) }).collect()
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-12 * b.abs().max(1.0)
}

#[test]
fn time_to_reach_interpolates_a_power_law_exactly() {
    for t in [0.25, 0.3, 1.0, 3.7, 16.0] {
        let Reach::At { seconds, spp } = time_to_reach(&raw(), C / t) else { panic!("{t} s lies on the ladder") };
        assert!(close(seconds, t) && close(spp, t / 0.25), "{t}: {seconds} s, {spp} spp");
    }
}

#[test]
fn error_at_interpolates_a_power_law_exactly() {
    for t in [0.25, 0.3, 1.0, 3.7, 16.0] {
        let e = error_at(&raw(), t).unwrap();
        assert!(close(e, C / t), "{t}: {e}");
    }
    assert_eq!(error_at(&raw(), 0.2), None, "before the first rung");
    assert_eq!(error_at(&raw(), 16.5), None, "after the last rung");
}

#[test]
fn errors_outside_the_ladder_are_not_extrapolated() {
    assert_eq!(time_to_reach(&raw(), C / 20.0), Reach::BelowLadder);
    assert_eq!(time_to_reach(&raw(), C / 0.2), Reach::AboveLadder);
    assert_eq!(time_to_reach(&raw()[..1], C / 0.25), Reach::NoLadder);
    assert_eq!(time_to_reach(&raw(), 0.0), Reach::NoLadder);
}

/// A noisy ladder whose error rises between two rungs: the first crossing along the ladder counts.
#[test]
fn a_non_monotone_ladder_gives_the_first_crossing() {
    let raw = [
        Point { spp: 1.0, seconds: 1.0, error: 1.0 },
        Point { spp: 2.0, seconds: 2.0, error: 0.25 },
        Point { spp: 4.0, seconds: 4.0, error: 0.5 },
        Point { spp: 8.0, seconds: 8.0, error: 0.1 },
    ];
    let Reach::At { seconds, .. } = time_to_reach(&raw, 0.5) else { panic!() };
    assert!(close(seconds, 2f64.powf(0.5)), "{seconds}");
}

fn row(method: &str, spp: u32, render: f64, denoise: Option<f64>, rel_mse: f64, ssim: f64) -> Row {
    let m = Metrics {
        psnr: 30.0,
        ssim,
        mae: 0.0,
        mse: 0.0,
        rel_mse,
        ms_ssim: None,
        flip: None,
        color_shift: None,
        exposure: 1.0,
    };
    let mut r = Row::new("v", method, spp, &m);
    r.render_seconds = Some(render);
    r.denoise_seconds = denoise;
    r
}

/// A denoiser at 1 spp (render 0.25 s + denoise 0.25 s = 0.5 s) with relMSE C / 2 = the error of raw path
/// tracing after 2 s = 8 spp: it reaches it in 25 % of the time; in its 0.5 s raw path tracing has C / 0.5,
/// 4× its error.
#[test]
fn compare_to_raw_gives_equal_error_and_equal_time() {
    let mut rows: Vec<Row> = raw().iter().map(|p| row("noisy", p.spp as u32, p.seconds, None, p.error, 0.9)).collect();
    rows.push(row("reference", 1024, 300.0, None, 0.0, 1.0));
    rows.push(row("net", 1, 0.25, Some(0.25), C / 2.0, 0.99));
    let all = tradeoff::compare_to_raw(&rows);
    assert_eq!(all.len(), 2, "one per metric: {all:?}");
    let c = all.iter().find(|c| c.metric == ErrorMetric::RelMse).unwrap();
    assert!(close(c.seconds, 0.5) && close(c.raw_seconds.unwrap(), 2.0) && close(c.raw_spp.unwrap(), 8.0), "{c:?}");
    assert!(close(c.time_percent.unwrap(), 25.0) && close(c.raw_error_same_time.unwrap(), C / 0.5), "{c:?}");
    assert_eq!(c.status, "interpolated");
    assert!(c.sentence().contains("reaches the error of raw 8.0 spp in 25.0 % of its time"), "{}", c.sentence());
    assert!(c.sentence().contains("(4.00× the error)"), "{}", c.sentence());

    // 1 − SSIM is 0.01 for the denoiser and 0.1 on every rung: below the ladder, said so.
    let s = all.iter().find(|c| c.metric == ErrorMetric::OneMinusSsim).unwrap();
    assert_eq!((s.status.as_str(), s.raw_seconds, s.time_percent), ("below_ladder", None, None));
    assert!(s.sentence().contains("does not reach this error within its spp ladder (not extrapolated)"));
    // Below the ladder's last rung (64 spp in 16 s) in 0.5 s: 3.125 % of that render's time, an upper bound.
    assert_eq!(s.top_spp, Some(64.0));
    assert!(close(s.top_time_percent.unwrap(), 3.125), "{s:?}");
    assert!(
        s.sentence().contains("below raw path tracing's error at the ladder's highest spp (64) in 3.1 % of"),
        "{}",
        s.sentence()
    );
    let o = tradeoff::overview(&all);
    let o = o.iter().find(|o| o.metric == ErrorMetric::OneMinusSsim).unwrap();
    assert_eq!((o.interpolated, o.top_spp), (0, Some(64.0)));
    assert!(close(o.median_top_time_percent.unwrap(), 3.125), "{o:?}");
    // An interpolated comparison has no top rung.
    assert_eq!((c.top_spp, c.top_time_percent), (None, None));
}

#[test]
fn csv_has_a_line_per_timed_row_and_quotes_names() {
    let rows = vec![
        row("noisy", 1, 0.25, None, 2.0, 0.5),
        row("reference", 1024, 300.0, None, 0.0, 1.0),
        row("run \"a\", b", 1, 0.25, Some(0.5), 0.5, 0.75),
    ];
    let csv = tradeoff::to_csv(&rows);
    assert_eq!(
        csv,
        "view,method,spp,render_seconds,denoise_seconds,seconds,rel_mse,one_minus_ssim\n\
         v,noisy,1,0.25,,0.25,2,0.5\n\
         v,\"run \"\"a\"\", b\",1,0.25,0.5,0.75,0.5,0.25\n"
    );
}

/// Over views, the medians count only the views raw path tracing reaches; the others are counted as compared.
#[test]
fn overview_takes_medians_over_the_views_reached() {
    let mut rows = Vec::new();
    // Three views with the same raw ladder; the denoiser at 1 spp (0.5 s) reaches C / 2, C / 4 and C / 100
    // (8 and 16 spp in 25 % and 12.5 % of the time; the last is below the ladder).
    for (view, error) in [("a", C / 2.0), ("b", C / 4.0), ("c", C / 100.0)] {
        for p in raw() {
            let mut r = row("noisy", p.spp as u32, p.seconds, None, p.error, 0.9);
            r.view = view.into();
            rows.push(r);
        }
        let mut r = row("net", 1, 0.25, Some(0.25), error, 0.9);
        r.view = view.into();
        rows.push(r);
    }
    let overview = tradeoff::overview(&tradeoff::compare_to_raw(&rows));
    let o = overview.iter().find(|o| o.metric == ErrorMetric::RelMse).unwrap();
    assert_eq!((o.method.as_str(), o.spp, o.views, o.interpolated), ("net", 1, 3, 2));
    assert!(close(o.median_time_percent.unwrap(), 18.75) && close(o.median_raw_spp.unwrap(), 12.0), "{o:?}");
    // Equal time (0.5 s): raw has C / 0.5 = 2 C against C / 2, C / 4, C / 100: ratios 4, 8, 200.
    assert!(close(o.median_error_ratio_same_time.unwrap(), 8.0), "{o:?}");
}
