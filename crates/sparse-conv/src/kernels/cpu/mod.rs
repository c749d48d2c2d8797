//! The sparse convolution and batch norm over plain slices: forward, feature gradient, weight
//! gradient, and the norm's statistics, normalisation and gradients. Every CPU backend calls these;
//! the GPU kernels compute the same sums.
//!
//! Determinism: every output row sums its offsets in one fixed order, and the weight gradient's
//! partial sums are cut at sizes that depend only on the problem, never on the number of threads,
//! so results are bit-identical at any thread count (no atomics, no two tasks writing one row).
//!
//! Layout: [`Element`] (`element`) is what the kernels share and the leaf every other file here
//! depends on; `conv` and [`norm`] are the general kernels; `native` gives f32 its hooks into
//! `micro`, the f32 register-tile kernels written once over `simd`'s vector type (AVX-512F,
//! AVX2 + FMA), which fall back on nothing but `element` and `conv`; `peak` times the cores'
//! multiply-add peak on the same vector type, and the forward's register tile on cached rows,
//! for the benchmarks.

pub mod adam;
mod conv;
mod element;
// Until a NEON `Simd` lands, other architectures instantiate none of the SIMD kernels.
#[cfg_attr(not(target_arch = "x86_64"), allow(dead_code, unused_imports, unused_macros))]
mod micro;
#[cfg_attr(not(target_arch = "x86_64"), allow(unreachable_code, unused_imports, unused_variables))]
mod native;
pub mod norm;
#[cfg_attr(not(target_arch = "x86_64"), allow(dead_code, unused_imports, unreachable_code))]
mod peak;
#[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
mod simd;

pub use conv::{pair_conv, weight_grad};
pub use element::{Element, PairDirection, RowEpilogue};
pub(crate) use element::filled_in_chunks;
pub(crate) use simd::Level;
pub use peak::{cached_tile_gflops, fma_peak_gflops};
pub use simd::{cpu_features, cpu_kernel_path};
