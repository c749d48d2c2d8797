//! What the workspace's benchmark binaries measure with: medians (and minima) after warm-up, and
//! peak memory. The time spent inside the op's kernels is counted by [`sparse_conv::profile`].

use serde::Serialize;
use std::time::Instant;

/// Wall times of repeated calls, in milliseconds. On a shared or virtual machine the minimum is
/// the steadier figure (other load only ever adds time); the median is the typical one.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct Timing {
    /// Median.
    pub median_ms: f64,
    /// Minimum.
    pub min_ms: f64,
}

/// Median and minimum wall time of `runs` calls of `f` after `warmup` untimed calls.
pub fn time_ms(warmup: usize, runs: usize, mut f: impl FnMut()) -> Timing {
    for _ in 0..warmup {
        f();
    }
    let mut times: Vec<f64> = (0..runs.max(1))
        .map(|_| {
            let t = Instant::now();
            f();
            t.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    times.sort_by(f64::total_cmp);
    let m = times.len() / 2;
    let median_ms = if times.len() % 2 == 1 { times[m] } else { (times[m - 1] + times[m]) / 2.0 };
    Timing { median_ms, min_ms: times[0] }
}

/// Median wall time of `runs` calls of `f` after `warmup` untimed calls, in milliseconds.
pub fn median_ms(warmup: usize, runs: usize, f: impl FnMut()) -> f64 {
    time_ms(warmup, runs, f).median_ms
}

/// Peak resident set size of this process (Linux `VmHWM`), in MiB; 0 where unavailable.
pub fn peak_rss_mb() -> f64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| s.lines().find(|l| l.starts_with("VmHWM:")).and_then(|l| l.split_whitespace().nth(1)?.parse::<f64>().ok()))
        .map_or(0.0, |kb| kb / 1024.0)
}
