//! The op's own counters: time spent in each kind of kernel and the convolutions' operations,
//! process-wide, a few atomic additions per call. The benchmark binaries read them to split a
//! step's time between the kernels and everything around them.

use serde::Serialize;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

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
    /// The GPU gather's tile plans ([`crate::geometry::row_tiles::RowTiles`]), made on the host.
    TilePlan = 5,
    /// Copying a map's tables and tile plans to a GPU.
    Upload = 6,
    /// The host's side of launching pmunet's GPU kernels, the op's and Adam's (they run
    /// asynchronously: this is the time the host spends queuing them, not theirs).
    GpuDispatch = 7,
}

static KERNEL_NANOS: [AtomicU64; 8] = [const { AtomicU64::new(0) }; 8];

/// Floating-point operations of the convolution kernels run so far (2 per multiply-add).
static CONV_FLOPS: AtomicU64 = AtomicU64::new(0);

/// Adds a convolution kernel's `2·pairs·c_in·c_out` operations to the process-wide count, so the
/// benchmarks can set a network's conv time against the machine's GEMM ceiling.
pub(crate) fn count_conv_flops(pairs: usize, c_in: usize, c_out: usize) {
    CONV_FLOPS.fetch_add(2 * (pairs * c_in * c_out) as u64, Ordering::Relaxed);
}

/// Times the op's GPU path read something back from the device (each waits for what is queued).
static READ_BACKS: AtomicU64 = AtomicU64::new(0);

/// Counts one read-back of the op's GPU path (a level's voxel count or coordinates).
#[cfg_attr(not(feature = "cube"), allow(dead_code))]
pub(crate) fn count_read_back() {
    READ_BACKS.fetch_add(1, Ordering::Relaxed);
}

/// Runs `f`, adding its wall time to `kernel`'s process-wide total. The CPU backends wrap their
/// kernels in it, so the benchmarks can print what the rest of a step (Burn's graph, its
/// elementwise ops, the optimiser) costs beside them. On a GPU backend it counts the host's parts
/// of the op (maps, tile plans, uploads, dispatch); the kernels themselves are asynchronous and
/// not counted. Calls must not nest.
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
    /// GPU tile plans, on the host.
    pub tile_plan_ms: f64,
    /// Map tables and tile plans copied to a GPU.
    pub upload_ms: f64,
    /// The host's side of launching the op's GPU kernels.
    pub gpu_dispatch_ms: f64,
    /// Operations of the three convolution kernels, in GFLOP (2 per multiply-add).
    pub conv_gflop: f64,
    /// Read-backs from the device on the op's GPU path (none when the host counted every level).
    pub read_backs: f64,
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
            tile_plan_ms: ms(Kernel::TilePlan),
            upload_ms: ms(Kernel::Upload),
            gpu_dispatch_ms: ms(Kernel::GpuDispatch),
            conv_gflop: CONV_FLOPS.load(Ordering::Relaxed) as f64 / 1e9,
            read_backs: READ_BACKS.load(Ordering::Relaxed) as f64,
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
            tile_plan_ms: d(self.tile_plan_ms, earlier.tile_plan_ms),
            upload_ms: d(self.upload_ms, earlier.upload_ms),
            gpu_dispatch_ms: d(self.gpu_dispatch_ms, earlier.gpu_dispatch_ms),
            conv_gflop: d(self.conv_gflop, earlier.conv_gflop),
            read_backs: d(self.read_backs, earlier.read_backs),
        }
    }

    /// GFLOP/s of the three convolution kernels together.
    pub fn conv_gflops(&self) -> f64 {
        self.conv_gflop / ((self.conv_forward_ms + self.conv_input_grad_ms + self.conv_weight_grad_ms) / 1e3)
    }

    /// All kinds together.
    pub fn total_ms(&self) -> f64 {
        self.map_build_ms + self.conv_forward_ms + self.conv_input_grad_ms + self.conv_weight_grad_ms + self.batch_norm_ms + self.gpu_host_ms()
    }

    /// The op's host work that only a GPU backend has: tile plans, uploads, dispatch.
    pub fn gpu_host_ms(&self) -> f64 {
        self.tile_plan_ms + self.upload_ms + self.gpu_dispatch_ms
    }
}
