//! Wall-clock timing with warm-up runs.

use std::time::Instant;

use serde::{Deserialize, Serialize};

/// Statistics of `runs` timed calls, in seconds.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Timing {
    pub median: f64,
    pub mean: f64,
    pub min: f64,
    pub max: f64,
    pub runs: usize,
}

/// Calls `f` `warmup` times untimed, then `n` times timed (at least once), and returns the statistics;
/// the median of an even count is the mean of the middle two. Results of `f` are passed through
/// `std::hint::black_box` so the work is not optimized away; capture outputs in the closure if needed.
///
/// ```
/// let t = hush_eval::time_median(5, 1, || (0..1000u64).sum::<u64>());
/// assert_eq!(t.runs, 5);
/// assert!(t.min <= t.median && t.median <= t.max);
/// ```
pub fn time_median<T>(n: usize, warmup: usize, mut f: impl FnMut() -> T) -> Timing {
    for _ in 0..warmup {
        std::hint::black_box(f());
    }
    let n = n.max(1);
    let mut times: Vec<f64> = (0..n)
        .map(|_| {
            let start = Instant::now();
            std::hint::black_box(f());
            start.elapsed().as_secs_f64()
        })
        .collect();
    times.sort_by(f64::total_cmp);
    let median = if n % 2 == 1 { times[n / 2] } else { 0.5 * (times[n / 2 - 1] + times[n / 2]) };
    Timing { median, mean: times.iter().sum::<f64>() / n as f64, min: times[0], max: times[n - 1], runs: n }
}
