//! What the workspace's benchmark binaries measure with: medians (and minima) after warm-up, peak
//! memory, and the time spent inside the CPU kernels.

use serde::Serialize;
use std::sync::atomic::{AtomicU64, Ordering};
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

/// The kinds of work [`in_kernel`] accounts for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kernel {
    /// Building kernel maps (and the coordinate index they need).
    MapBuild = 0,
    /// The sparse convolution's forward.
    ConvForward = 1,
    /// Its feature gradient.
    ConvInputGrad = 2,
    /// Its weight gradient.
    ConvWeightGrad = 3,
    /// Batch norm (+ ReLU), forward and backward.
    BatchNorm = 4,
}

static KERNEL_NANOS: [AtomicU64; 5] = [const { AtomicU64::new(0) }; 5];

/// Floating-point operations of the convolution kernels run so far (2 per multiply-add).
static CONV_FLOPS: AtomicU64 = AtomicU64::new(0);

/// Adds a convolution kernel's `2·pairs·c_in·c_out` operations to the process-wide count, so the
/// benchmarks can set a network's conv time against the machine's GEMM ceiling.
pub(crate) fn count_conv_flops(pairs: usize, c_in: usize, c_out: usize) {
    CONV_FLOPS.fetch_add(2 * (pairs * c_in * c_out) as u64, Ordering::Relaxed);
}

/// Runs `f`, adding its wall time to `kernel`'s process-wide total. The CPU backends wrap their
/// kernels in it, so the benchmarks can print what the rest of a step (Burn's graph, its
/// elementwise ops, the optimiser) costs beside them. GPU kernels are asynchronous and not
/// counted.
pub fn in_kernel<R>(kernel: Kernel, f: impl FnOnce() -> R) -> R {
    let t = Instant::now();
    let r = f();
    KERNEL_NANOS[kernel as usize].fetch_add(t.elapsed().as_nanos() as u64, Ordering::Relaxed);
    r
}

/// Totals of [`in_kernel`] since the process started, in milliseconds; differences of two
/// readings give a stretch of work's share.
#[derive(Debug, Clone, Copy, Default, Serialize, PartialEq)]
pub struct KernelTimes {
    /// Building kernel maps.
    pub map_build_ms: f64,
    /// Convolution forwards.
    pub conv_forward_ms: f64,
    /// Convolution feature gradients.
    pub conv_input_grad_ms: f64,
    /// Convolution weight gradients.
    pub conv_weight_grad_ms: f64,
    /// Batch norm, forward and backward.
    pub batch_norm_ms: f64,
    /// Operations of the three convolution kernels, in GFLOP (2 per multiply-add).
    pub conv_gflop: f64,
}

impl KernelTimes {
    /// The totals now.
    pub fn now() -> Self {
        let ms = |k: Kernel| KERNEL_NANOS[k as usize].load(Ordering::Relaxed) as f64 / 1e6;
        KernelTimes {
            map_build_ms: ms(Kernel::MapBuild),
            conv_forward_ms: ms(Kernel::ConvForward),
            conv_input_grad_ms: ms(Kernel::ConvInputGrad),
            conv_weight_grad_ms: ms(Kernel::ConvWeightGrad),
            batch_norm_ms: ms(Kernel::BatchNorm),
            conv_gflop: CONV_FLOPS.load(Ordering::Relaxed) as f64 / 1e9,
        }
    }

    /// `(self − earlier) / runs`: the mean per run of a stretch of `runs` runs.
    pub fn per_run_since(&self, earlier: &KernelTimes, runs: usize) -> KernelTimes {
        let d = |a: f64, b: f64| (a - b) / runs.max(1) as f64;
        KernelTimes {
            map_build_ms: d(self.map_build_ms, earlier.map_build_ms),
            conv_forward_ms: d(self.conv_forward_ms, earlier.conv_forward_ms),
            conv_input_grad_ms: d(self.conv_input_grad_ms, earlier.conv_input_grad_ms),
            conv_weight_grad_ms: d(self.conv_weight_grad_ms, earlier.conv_weight_grad_ms),
            batch_norm_ms: d(self.batch_norm_ms, earlier.batch_norm_ms),
            conv_gflop: d(self.conv_gflop, earlier.conv_gflop),
        }
    }

    /// GFLOP/s of the three convolution kernels together.
    pub fn conv_gflops(&self) -> f64 {
        self.conv_gflop / ((self.conv_forward_ms + self.conv_input_grad_ms + self.conv_weight_grad_ms) / 1e3)
    }

    /// All kinds together.
    pub fn total_ms(&self) -> f64 {
        self.map_build_ms + self.conv_forward_ms + self.conv_input_grad_ms + self.conv_weight_grad_ms + self.batch_norm_ms
    }
}
