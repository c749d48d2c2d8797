//! Data: the box type of the workspace, readers for the JRDB, KITTI object and nuScenes-style
//! layouts, batching, and a simulator that writes JRDB-format trees.
//!
//! Crate map:
//! - files: [`pcd`] (+ [`lzf`]), [`cloud`] (PCD, KITTI `.bin`, nuScenes `.pcd.bin`, `.npy` for detection), [`labels`], [`calibration`], [`timestamps`], [`split`] (layout and
//!   splits);
//! - datasets: [`dataset`] (`Dataset`, `Frame`) over JRDB trees, [`kitti`] and [`nuscenes`],
//!   their frames moved by [`rigid`]; [`export`] writes one in the others' layouts;
//! - settings: [`config`] (`DataConfig`, the `[data]` table a run embeds);
//! - batches: [`volume`] → [`augment`] → [`voxelize`] → [`batch`] (`Sample`, `Batch`), driven by [`loader`];
//! - checks: [`stats`], [`convention`];
//! - the built-in data: [`sim`] (`synth`).
#![warn(missing_docs)]

/// Training augmentation (scale, rotation about z).
pub mod augment;
/// Frames to samples to batches.
pub mod batch;
/// Point clouds from files other tools write (PCD, KITTI `.bin`, nuScenes `.pcd.bin`, NumPy `.npy`).
pub mod cloud;
/// The workspace's box type and its convention.
pub mod box3d;
/// LiDAR → base-frame transforms of `defaults.yaml`.
pub mod calibration;
/// The `[data]` settings of a run.
pub mod config;
/// A dataset written in KITTI's or nuScenes' layout.
pub mod export;
/// KITTI object's layout: calibration, labels, the camera's view.
pub mod kitti;
/// nuScenes-style tables.
pub mod nuscenes;
/// Rigid transforms between the datasets' frames.
pub mod rigid;
/// The box-convention check against `num_points`.
pub mod convention;
/// A split of a JRDB tree and its frames.
pub mod dataset;
/// Errors that name the file at fault.
pub mod error;
/// The ground under a sensor, fitted in its scan.
pub mod ground;
/// `labels_3d` JSON.
pub mod labels;
/// Seeded, shuffling, prefetching batch loader.
pub mod loader;
/// LZF block compression (PCD `binary_compressed`).
pub mod lzf;
/// PCD reader and writer.
pub mod pcd;
/// ROS's PointCloud2 message decoded into points.
pub mod pointcloud2;
/// The JRDB-format simulator.
pub mod sim;
/// Layout of a tree and its splits.
pub mod split;
/// Dataset statistics.
pub mod stats;
/// `frames_pc.json`.
pub mod timestamps;
/// The working volume points are cropped to.
pub mod volume;
/// Voxelization.
pub mod voxelize;

pub use augment::{AugmentConfig, Augmentation};
pub use batch::{Batch, Sample, SampleConfig, collate, prepare};
pub use box3d::Box3d;
pub use calibration::{Calibration, Lidar};
pub use cloud::{Cloud, CloudFormat, FORMATS, FormatInfo, ReadLimits, encode_npy, parse_cloud, parse_cloud_within, read_cloud};
pub use config::{AugmentSection, DataConfig, ExtraTree};
pub use dataset::{Dataset, DatasetConfig, DatasetFormat, Frame, OnBadFrame};
pub use kitti::KittiOptions;
pub use nuscenes::NuscenesOptions;
pub use rigid::Rigid;
pub use error::{DataError, ErrorKind, Result};
pub use labels::Label;
pub use loader::{Batches, Loader, LoaderConfig};
pub use pcd::{Encoding, NonFinite, PointCloud, read_pcd};
pub use split::{DEFAULT_VAL_SEQUENCES, Layout, Split};
pub use volume::Volume;
pub use voxelize::{Pooling, VoxelConfig, Voxels, voxelize};
