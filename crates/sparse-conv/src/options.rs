//! The op's kernel knobs: which CPU kernels run, when the GPU gather is tiled and where a GPU's
//! submanifold maps are built. The library
//! never reads the environment; an application sets these once, before its first convolution
//! (the runner from its config's `[kernels]` table, the benchmark binaries from their flags).

use std::sync::atomic::{AtomicBool, AtomicU8, AtomicUsize, Ordering};

use serde::{Deserialize, Serialize};

/// Which CPU kernels the op runs in f32.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum CpuKernels {
    /// The SIMD micro-kernels for the widest instructions the CPU has (AVX-512F, else AVX2 +
    /// FMA), the general gather–GEMM–scatter path on CPUs with neither.
    #[default]
    Auto,
    /// The AVX2 + FMA micro-kernels even where the CPU has AVX-512F (to compare or test them on
    /// one machine); the general path on CPUs without AVX2 + FMA.
    Avx2,
    /// The general path on every CPU (to compare; f64 always runs it).
    Generic,
}

impl CpuKernels {
    /// The choice as a byte, for the process-wide atomic (exhaustive both ways, so a new
    /// choice cannot be forgotten in one of them).
    fn to_byte(self) -> u8 {
        match self {
            Self::Auto => 0,
            Self::Avx2 => 1,
            Self::Generic => 2,
        }
    }

    fn from_byte(b: u8) -> Self {
        match b {
            0 => Self::Auto,
            1 => Self::Avx2,
            _ => Self::Generic,
        }
    }
}

/// Where a tensor on a GPU gets its coarse levels, its maps' tables and its tile plans.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum GpuMaps {
    /// Made on the device from the level's coordinates (`geometry::device_maps`, `device_down`,
    /// `device_tiles`); the levels' sizes are counted on the host, nothing is read back.
    #[default]
    Device,
    /// Made on the host and uploaded, as the CPU backends make them (to compare the two).
    Host,
}

/// Every knob of the op's kernels; the defaults are what the benchmarks chose. It is a TOML table
/// (`[kernels]` of a run's config) and a set of command-line flags (`--cpu-kernels`,
/// `--gpu-tiled-min-cubes`, `--gpu-maps`) alike.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, clap::Args)]
#[serde(default, deny_unknown_fields)]
pub struct KernelOptions {
    /// CPU kernels: `auto` (the widest SIMD micro-kernels the CPU has), `avx2` or `generic`.
    #[arg(long = "cpu-kernels", value_enum, default_value_t = CpuKernels::Auto)]
    pub cpu: CpuKernels,
    /// Fewest tiles (cubes) a GPU gather launch needs to run tiled (rows sorted by the offsets
    /// they use, staged in shared memory); smaller launches run untiled, which needs no tile
    /// plan. 0: always tiled. The default, 2048, is where the tiled kernel repaid
    /// its plan on an H100 (`crates/sparse-conv/README.md`).
    #[arg(long, default_value_t = DEFAULT_TILED_MIN_CUBES)]
    pub gpu_tiled_min_cubes: usize,
    /// Where a GPU tensor's levels, maps and tile plans are made: `device` or `host`.
    #[arg(long, value_enum, default_value_t = GpuMaps::Device)]
    pub gpu_maps: GpuMaps,
}

const DEFAULT_TILED_MIN_CUBES: usize = 2048;

impl Default for KernelOptions {
    fn default() -> Self {
        Self { cpu: CpuKernels::Auto, gpu_tiled_min_cubes: DEFAULT_TILED_MIN_CUBES, gpu_maps: GpuMaps::Device }
    }
}

/// [`CpuKernels`] as a byte ([`CpuKernels::to_byte`]).
static CPU: AtomicU8 = AtomicU8::new(0);
static TILED_MIN_CUBES: AtomicUsize = AtomicUsize::new(DEFAULT_TILED_MIN_CUBES);
static MAPS_ON_HOST: AtomicBool = AtomicBool::new(false);

impl KernelOptions {
    /// Makes these the options of every later convolution in the process. Set them before the
    /// first one: results are bit-identical at every thread count for a given choice, and the
    /// SIMD levels give each other's bits; the general path differs from them in the last bits.
    pub fn apply(self) {
        CPU.store(self.cpu.to_byte(), Ordering::Relaxed);
        TILED_MIN_CUBES.store(self.gpu_tiled_min_cubes, Ordering::Relaxed);
        MAPS_ON_HOST.store(self.gpu_maps == GpuMaps::Host, Ordering::Relaxed);
    }

    /// The options in effect.
    pub fn current() -> Self {
        let cpu = CpuKernels::from_byte(CPU.load(Ordering::Relaxed));
        let gpu_maps = if MAPS_ON_HOST.load(Ordering::Relaxed) { GpuMaps::Host } else { GpuMaps::Device };
        Self { cpu, gpu_tiled_min_cubes: TILED_MIN_CUBES.load(Ordering::Relaxed), gpu_maps }
    }
}
