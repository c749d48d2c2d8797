//! What the benchmark binaries use and the library does not: timing helpers and the standard
//! voxel scenes.

pub mod scene;
pub mod timing;
