//! Detectors as Burn modules: Person-MinkUNet (sparse) and the CenterPoint-style dense baseline,
//! behind one [`Detector`] interface and configured by one serde [`ModelConfig`].
//!
//! Crate map:
//! - [`config`]: [`ModelConfig`], the `[model]` table of a run's TOML (which detector, and its
//!   settings).
//! - [`detector`]: the [`Detector`] interface, [`LossTerms`], [`Detections`].
//! - [`person_minkunet`]: the sparse detector (backbone, box coder, targets, loss, decoding and
//!   its config, one file each).
//! - [`centerpoint`]: the dense baseline, laid out the same way (encoder, grid, backbone, head,
//!   targets, loss, decoding, config).
//! - [`post`]: score threshold, NMS, box voting and caps, shared by both.
//! - [`test_time`]: the cloud seen at half or quarter turns and the passes fused
//!   ([`GridTurn`], [`fuse`]), applied where a trained model detects (`train::RunDetector`).
//! - [`facing`]: the second stage that turns a box's heading to the direction the points in it
//!   show (fitted per run; IoU does not see the direction, so AP does not change).
//!
//! A trained model on point clouds of your own: `train::RunDetector` loads a run folder (config
//! and checkpoint) once and detects in `[x, y, z]` arrays (`crates/train/examples/detect_points.rs`);
//! `train detect` (files, folders, trees) and `train serve` (HTTP) wrap it (`docs/detect.md`).

#![warn(missing_docs)]

/// The dense CenterPoint-style baseline.
pub mod centerpoint;
/// The model a run trains.
pub mod config;
/// The interface both detectors implement.
pub mod detector;
/// Which way a detected person faces, read from the points in the box.
pub mod facing;
/// Person-MinkUNet.
pub mod person_minkunet;
/// Post-processing shared by both models.
pub mod post;
/// Test-time turns and the fusion of their detections.
pub mod test_time;

pub use centerpoint::{CenterPoint, CenterPointConfig};
pub use config::ModelConfig;
pub use detector::{Detections, Detector, LossTerms};
pub use facing::{FacingClassifier, FacingFeatures, FacingSample};
pub use person_minkunet::{BoxCoder, BoxFrame, MinkUNet, MinkUNetConfig, PersonMinkUNet, PersonMinkUNetConfig, TargetVariant, UNetLevels};
pub use post::{NmsKind, PostProcessConfig};
pub use test_time::{GridTurn, focus, fuse, turned_batch};
