//! The pmunet experiment runner: one TOML file trains and evaluates a detector; a sweep file runs
//! variants × seeds and tabulates them.
//!
//! Crate map:
//! - setup: [`config`] (the run's TOML), [`schedule`] (lr, the authors' decay), [`backend`]
//!   (flex, ndarray, wgpu; threads), [`data`] (simulated data on first use, splits, loaders);
//! - a run: [`run_dir`] (the folder), [`trainer`] (the loop; [`data_parallel`] over several
//!   devices), [`validate`] (AP3D with `eval`),
//!   [`checkpoint`] (atomic best/latest, resume), [`metrics`] (CSV), [`plots`] (PNG), [`progress`];
//! - after a run: [`detector`] ([`RunDetector`]: a run's model on point clouds), [`infer`]
//!   (detection files, official layout, scores), [`calibrate`] (the radial shift of
//!   post-processing, measured on frames not scored), [`facing`] (the checkpoint's facing stage,
//!   fitted on frames not scored), [`render`] (BEV PNGs);
//! - on the user's own clouds: [`sensor_pose`] (their frame in JRDB's), [`detect`] (files,
//!   folders, trees → JSON, KITTI txt, PNG), [`serve`] (the same over HTTP);
//! - many runs: [`sweep`] (its [`sweep::Executor`] seam: the local runner today), [`stats`],
//!   [`soup`] (runs fine-tuned from one set of weights, averaged into one).
//!
//! The binary (`cargo run -p train -- --help`) wraps [`trainer::train`], [`infer::infer`],
//! [`sweep::run_sweep`], [`detect::detect`] and [`serve::serve`].
#![warn(missing_docs)]

/// Backend choice and threads.
pub mod backend;
/// The centres' bias along the sensor's ray, and the shift that corrects it.
pub mod calibrate;
/// Atomic checkpoints and the loop state.
pub mod checkpoint;
/// The run configuration (TOML).
pub mod config;
/// Datasets and loaders of a run.
pub mod data;
/// Training on several devices of one machine: a batch's parts, gradients averaged.
pub mod data_parallel;
/// A trained detector loaded from a run folder, applied to point clouds.
pub mod detector;
/// People in point-cloud files, folders and trees.
pub mod detect;
/// The facing stage of a checkpoint, fitted on its own boxes.
pub mod facing;
/// Recordings of point clouds (MCAP, ROS 2 SQLite bags, ROS 1 bags), read message by message.
pub mod recording;
/// Detections as an MCAP scene Foxglove and Lichtblick open.
pub mod scene;
/// Detection files and scores from a checkpoint.
pub mod infer;
/// CSV curves.
pub mod metrics;
/// PNG plots.
pub mod plots;
/// Progress bars.
pub mod progress;
/// Bird's-eye-view images.
pub mod render;
/// The run folder.
pub mod run_dir;
/// Learning-rate schedules.
pub mod schedule;
/// A user's sensor frame in JRDB's base frame.
pub mod sensor_pose;
/// The detection service over HTTP.
pub mod serve;
/// Mean, spread and 95 % intervals over seeds.
pub mod stats;
/// Several runs' weights averaged into one network.
pub mod soup;
/// Sweeps over variants and seeds, run by an [`sweep::Executor`].
pub mod sweep;
/// The training loop.
pub mod trainer;
/// Validation.
pub mod validate;

pub use backend::BackendKind;
pub use calibrate::{CalibrateOptions, RadialBias, calibrate};
pub use checkpoint::{Checkpoints, Slot, TrainState};
pub use config::RunConfig;
pub use detect::{BoxRecord, DetectOptions, FrameReport, Found, find_people, find_people_placed};
pub use detector::RunDetector;
pub use facing::{FacingOptions, FacingReport, FitBoxes, fit_facing};
pub use infer::{InferOptions, InferOutput, infer};
pub use run_dir::{Existing, RunDir};
pub use schedule::Schedule;
pub use sensor_pose::{FrameSpec, Placement, SensorPose};
pub use serve::ServeOptions;
pub use soup::{SoupReport, soup};
pub use sweep::{SweepConfig, SweepResults, run_sweep};
pub use trainer::{TrainOptions, TrainSummary, train, train_model};
pub use validate::{FrameResult, Validation, validate};
