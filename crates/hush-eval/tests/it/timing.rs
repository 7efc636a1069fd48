use hush_eval::time_median;

#[test]
fn runs_warmup_then_n_timed_calls() {
    let mut calls = 0;
    let t = time_median(4, 2, || {
        calls += 1;
        std::thread::sleep(std::time::Duration::from_millis(if calls == 6 { 20 } else { 1 }));
    });
    assert_eq!(calls, 6);
    assert_eq!(t.runs, 4);
    assert!(t.min <= t.median && t.median <= t.max && t.min <= t.mean && t.mean <= t.max);
    assert!(t.max >= 0.02, "the slow last call is the max: {t:?}");
    assert!(t.median < 0.015, "the median ignores one outlier: {t:?}");
    assert_eq!(time_median(0, 0, || ()).runs, 1, "at least one timed run");
}
