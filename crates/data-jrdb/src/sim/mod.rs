//! The simulator: ray-cast scans of JRDB-like scenes with people, written as a JRDB-format tree.

/// `[data.simulate]`: the tree to generate when a run's data root is missing.
pub mod config;
pub mod geometry;
pub mod lidar;
pub mod people;
pub mod scene;
pub mod writer;

pub use config::SimulateConfig;
pub use writer::{Naming, Preset, SynthConfig, SynthSummary, names_for, sequence_names, synth};
