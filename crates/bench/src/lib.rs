//! What pmunet's benchmark binaries share and the libraries do not need: the standard voxel
//! scenes, timing and peak memory, what `model-bench` measures, and the process heap policy that
//! the benchmarks and the runner set at start-up.
//!
//! - [`backend`]: the backend a binary runs on (`--backend`) and its device.
//! - [`scene`]: voxel scenes (a `.npy` file or the built-in synthetic one).
//! - [`timing`]: medians and minima after warm-up, peak resident memory.
//! - [`model`]: an inference pass and a training step of either detector, timed.
//! - [`heap`]: freed tensor memory stays in the process (glibc).
//!
//! Binaries: `sparse-conv-bench` (the op alone), `model-bench` (a whole detector).

#![warn(missing_docs)]

pub mod backend;
pub mod heap;
pub mod model;
pub mod scene;
pub mod timing;
