//! The simulator: ray-cast scans of JRDB-like scenes with people, written as a JRDB-format tree.

pub mod geometry;
pub mod lidar;
pub mod people;
pub mod scene;
pub mod writer;

pub use writer::{Naming, Preset, SynthConfig, SynthSummary, names_for, sequence_names, synth};
