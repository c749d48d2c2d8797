//! The simulator: ray-cast scans of JRDB-like scenes (`bench-v1`) and of streets, campuses and
//! cluttered halls seen by many sensors on many platforms (`bench-v2`), written as a JRDB-format tree.

/// `[data.simulate]`: the tree to generate when a run's data root is missing.
pub mod backdrop;
pub mod config;
pub mod geometry;
pub mod lidar;
pub mod objects;
pub mod people;
pub mod rig;
pub mod scene;
pub mod sensors;
mod street;
pub mod thin;
pub mod world_v2;
pub mod writer;

pub use config::SimulateConfig;
pub use writer::{Naming, Preset, SynthConfig, SynthSummary, World, names_for, sequence_names, synth};
