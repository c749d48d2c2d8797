//! Detectors as Burn modules: Person-MinkUNet (sparse) and the CenterPoint-style dense baseline,
//! behind one [`Detector`] interface and configured by one serde [`ModelConfig`].
//!
//! Crate map:
//! - [`config`]: [`ModelConfig`] and the serde configs of both models (what TOML holds).
//! - [`detector`]: the [`Detector`] interface, [`LossTerms`], [`Detections`].
//! - Person-MinkUNet: [`minkunet`] (backbone, spec §1.6) → [`person_minkunet`] (head, spec §1.8)
//!   with [`box_coder`] (§1.8), [`targets`] (§1.9), [`loss`] (§1.10), [`decode`] (§1.12).
//! - [`centerpoint`]: the dense baseline (spec §4): encoder, backbone, head, targets, loss, decode.
//! - [`post`]: score threshold, NMS and cap shared by both models.
//! - [`bench`]: what the `model-bench` binary measures.

/// Timing and memory of a forward pass and a training step.
pub mod bench;
/// Person-MinkUNet's box encoding.
pub mod box_coder;
/// The dense CenterPoint-style baseline.
pub mod centerpoint;
/// Serde configs of both models.
pub mod config;
/// Person-MinkUNet's decoding.
pub mod decode;
/// The interface both detectors implement.
pub mod detector;
/// Person-MinkUNet's loss.
pub mod loss;
/// The MinkUNet backbone.
pub mod minkunet;
/// Person-MinkUNet: backbone + head.
pub mod person_minkunet;
/// Post-processing shared by both models.
pub mod post;
/// Person-MinkUNet's targets.
pub mod targets;

pub use box_coder::BoxCoder;
pub use centerpoint::CenterPoint;
pub use config::{CenterPointConfig, ModelConfig, NmsKind, PersonMinkUNetConfig, PostProcessConfig, TargetVariant};
pub use detector::{Detections, Detector, LossTerms};
pub use minkunet::{MinkUNet, MinkUNetConfig, UNetLevels};
pub use person_minkunet::PersonMinkUNet;
