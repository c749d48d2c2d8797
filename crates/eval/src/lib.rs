//! Box geometry and metrics for pmunet: rotated BEV / 3D IoU, NMS, and the JRDB 3D detection AP
//! computed *exactly* as the official `detection_eval/evaluate_object.cpp` of
//! `JRDB-dataset/jrdb_toolkit` does, so a number from pmunet is the leaderboard's number.
//!
//! Crate map:
//! - [`geometry`]: exact convex clipping, [`bev_iou`], [`iou_3d`] of [`Box3d`].
//! - [`nms`]: Person-MinkUNet's distance NMS ([`nms_distance`]), circle NMS ([`nms_circle`]),
//!   rotated-IoU NMS ([`nms_bev_iou`]) and box voting ([`nms::vote`]).
//! - [`kitti`]: the official 17-column txt format and the official JRDB → KITTI conversion.
//! - [`jrdb`]: JRDB `labels_3d` JSON (ground truth) and pmunet's detection JSON (schema documented there).
//! - [`dataset`]: pairing GT and detection files into [`Frame`]s, writing the official txt tree.
//! - [`ap`]: the official protocol (filters, two matching passes, 41 thresholds, AP) and named variants.
//! - [`centre`]: bird's-eye-centre AP (not a JRDB metric), for real scans labelled by other conventions.
//! - [`report`]: AP3D/APBEV at 0.3/0.5/0.7, per-sequence AP, table, JSON, PR CSV.
//! - [`plot`]: PR curves as PNG.
//!
//! The CLI (`cargo run -p eval -- --gt GT --det DET`) wraps [`dataset::load`] and [`Report`].
//!
//! pmunet's detection files (JSON, one per sequence, `DIR/<sequence>.json`; see [`jrdb`]):
//! ```json
//! {"sequence": "<sequence>",
//!  "detections": {"000123": [{"box": {"cx": 1.0, "cy": 2.0, "cz": 0.1, "l": 0.9, "w": 0.5,
//!                                     "h": 1.7, "rot_z": 0.3}, "score": 0.93}]}}
//! ```
//! `box` is a [`Box3d`] (JRDB base frame, l along the heading, z spans cz ± h/2). Every GT frame
//! needs a key (an empty list is fine). The same detections as the official txt tree:
//! [`dataset::write_kitti_tree`] or the CLI's `--write-kitti-det DIR`.
//!
//! Known, deliberate differences from the official tool, all on inputs it mishandles: a malformed
//! line is an error here (the tool misparses it or loops on it); negative box sizes are rejected; only
//! `*.txt` files of a sequence folder are read (the tool reads every entry); the tool's check that
//! the GT is the 27661-frame test set is not made.

#![warn(missing_docs)]

/// Official protocol: filters, matching, thresholds, AP.
pub mod ap;
/// Bird's-eye-centre AP (not a JRDB metric), for scans labelled by other conventions.
pub mod centre;
/// Reading GT and detections into frames; writing the official tree.
pub mod dataset;
/// The crate's error type.
pub mod error;
/// Rotated BEV and 3D IoU.
pub mod geometry;
/// JRDB labels_3d and pmunet detection JSON.
pub mod jrdb;
/// The official KITTI-style txt format.
pub mod kitti;
/// Non-maximum suppression and box voting.
pub mod nms;
/// PR curve PNG.
pub mod plot;
/// Table, JSON and CSV of a full evaluation.
pub mod report;

pub use ap::{Curve, Frame, Interpolation, Overlap, Protocol, evaluate};
pub use data_jrdb::Box3d;
pub use error::{EvalError, Result};
pub use geometry::{bev_iou, iou_3d};
pub use nms::{NmsConfig, nms_bev_iou, nms_circle, nms_distance};
pub use report::Report;
